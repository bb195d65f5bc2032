# Sourced by bootstrap, env.sh and lock: the ROS 2 distribution to use and its folders.
#   G2P_ROS_DISTRO=kilted (default) or jazzy (the Raspberry Pi's). Each has its own pinned lock file
#   (constraints/<distro>.txt), virtualenv and colcon build and install folders, so both can coexist.
# Sets g2p_distro, g2p_venv, g2p_build, g2p_install (absolute paths under the repository root $1).
g2p_distro="${G2P_ROS_DISTRO:-kilted}"
case "$g2p_distro" in
  kilted) _g2p_suffix="" ;;
  jazzy) _g2p_suffix="-jazzy" ;;
  *)
    echo "G2P_ROS_DISTRO=$g2p_distro: choose kilted or jazzy" >&2
    return 2
    ;;
esac
g2p_venv="$1/.venv$_g2p_suffix"
g2p_build="$1/build$_g2p_suffix"
g2p_install="$1/install$_g2p_suffix"
unset _g2p_suffix
