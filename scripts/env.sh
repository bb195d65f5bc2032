# Source this file to use the project's ROS 2 environment (after scripts/bootstrap):
#   source scripts/env.sh
# It activates .venv, sources install/setup.bash and keeps DDS on loopback.
_g2p_root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
# shellcheck disable=SC1091
source "$_g2p_root/.venv/bin/activate"
# The venv holds the ROS 2 core; install/setup.bash does not add it, so export it first.
export AMENT_PREFIX_PATH="$VIRTUAL_ENV${AMENT_PREFIX_PATH:+:$AMENT_PREFIX_PATH}"
# shellcheck disable=SC1091
source "$_g2p_root/install/setup.bash"
export RMW_IMPLEMENTATION=rmw_fastrtps_cpp
# Fast DDS would otherwise send discovery traffic out of the machine's network interfaces.
export ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST
unset _g2p_root
