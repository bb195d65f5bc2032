# Source this file to use the project's ROS 2 environment (after scripts/bootstrap):
#   source scripts/env.sh                         ROS 2 Kilted
#   G2P_ROS_DISTRO=jazzy source scripts/env.sh    ROS 2 Jazzy
# It activates the distribution's virtualenv, sources its install/setup.bash and keeps DDS on loopback.
_g2p_root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
# shellcheck source=scripts/distro.sh
source "$_g2p_root/scripts/distro.sh" "$_g2p_root" || return
# shellcheck disable=SC1091
source "$g2p_venv/bin/activate"
# The venv holds the ROS 2 core; install/setup.bash does not add it, so export it first.
export AMENT_PREFIX_PATH="$VIRTUAL_ENV${AMENT_PREFIX_PATH:+:$AMENT_PREFIX_PATH}"
# shellcheck disable=SC1091
source "$g2p_install/setup.bash"
export G2P_ROS_DISTRO="$g2p_distro"
export RMW_IMPLEMENTATION=rmw_fastrtps_cpp
# Fast DDS would otherwise send discovery traffic out of the machine's network interfaces.
export ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST
unset _g2p_root g2p_distro g2p_venv g2p_build g2p_install
