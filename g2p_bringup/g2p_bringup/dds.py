"""The Fast DDS settings of the graph: the one-host profile, and a UDP-only profile for two hosts.

One host: `config/fastdds_discovery.xml` (faster participant announcements and heartbeats); discovery
stays on loopback (ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST). Two hosts (`bringup --host rig|workstation`):
a profile written for the interface the user names, so DDS uses that interface only, over UDPv4 only
(shared memory would bypass the network between processes that share /dev/shm), in messages no larger
than one Ethernet frame (a sample lost on a lossy link is resent fragment by fragment rather than as
64 kB IP-fragmented datagrams, which lose a fragment far more often). Both are templates filled in for
the installed Fast DDS (2.x and 3.x name some XML elements differently).
"""

from __future__ import annotations

import fcntl
import shutil
import socket
import struct
import subprocess
from pathlib import Path
from xml.etree import ElementTree

from ament_index_python.packages import get_package_share_directory

# The variables naming Fast DDS's XML profiles file: 3.x (Kilted and later) reads the first, 2.x (Jazzy)
# the second. Each reads only its own; setting both makes 3.x load the file twice and reject its profile.
PROFILE_VARIABLES = ("FASTDDS_DEFAULT_PROFILES_FILE", "FASTRTPS_DEFAULT_PROFILES_FILE")

# Largest RTPS message on the two-host link (bytes): fits a 1500-byte MTU with the IP and UDP headers.
TWO_HOST_MAX_MESSAGE_BYTES = 1400

_SIOCGIFADDR = 0x8915


def clean_shared_memory() -> str:
    """Remove the Fast DDS shared-memory files in /dev/shm whose owners are dead (`fastdds shm clean`).

    A process that is killed (kill -9, a crash, a power cut of the Pi's supply but not its SD card...)
    leaves its shared-memory port and segment files, about 540 kB each, which nothing removes: they do not
    slow a later graph (docs/RESULTS.md, "Stale shared memory"), but they accumulate until /dev/shm is full
    and Fast DDS can create no more ("Failed to create segment"). Files in use by running processes are
    left alone, so this is safe beside any running ROS 2 graph.

    Returns:
        What the tool reported ("" when the `fastdds` tool is not on PATH, or failed).
    """
    tool = shutil.which("fastdds")
    if tool is None:
        return ""
    try:
        done = subprocess.run([tool, "shm", "clean"], capture_output=True, text=True, timeout=30)
    except (OSError, subprocess.TimeoutExpired):
        return ""
    return " ".join(done.stdout.split()) if done.returncode == 0 else ""


def profile_variable() -> str:
    """The variable the installed Fast DDS reads its profiles file from.

    rmw_fastrtps 9 and later (Kilted on) are built on Fast DDS 3; rmw_fastrtps 8 (Jazzy) on Fast DDS 2.
    """
    package_xml = Path(get_package_share_directory("rmw_fastrtps_cpp")) / "package.xml"
    version = ElementTree.parse(package_xml).getroot().findtext("version", "0")
    return PROFILE_VARIABLES[0] if int(version.split(".")[0]) >= 9 else PROFILE_VARIABLES[1]


def one_host_environment(environ: dict[str, str], directory: Path) -> dict[str, str]:
    """The variable to add to `environ` so that the installed Fast DDS loads the one-host profile.

    The profile is written into `directory` for the installed Fast DDS. Nothing when the user named a
    profiles file already (in either variable): theirs is used.
    """
    if any(environ.get(name) for name in PROFILE_VARIABLES):
        return {}
    profile = directory / "fastdds_discovery.xml"
    profile.write_text(_profile("fastdds_discovery.xml", {}))
    return {profile_variable(): str(profile)}


def _profile(template: str, values: dict[str, str]) -> str:
    """A profiles file of config/ filled in for the installed Fast DDS."""
    filled = {
        **values,
        # Fast DDS 3 renamed the XML elements of the writer's times.
        "@HEARTBEAT_PERIOD@": "heartbeat_period"
        if profile_variable() == PROFILE_VARIABLES[0]
        else "heartbeatPeriod",
    }
    text = (Path(get_package_share_directory("g2p_bringup")) / "config" / template).read_text()
    for placeholder, value in filled.items():
        text = text.replace(placeholder, value)
    return text


def interface_address(interface: str) -> str:
    """The IPv4 address of a network interface of this host (namespace).

    Raises:
        ValueError: no such interface, or it has no IPv4 address.
    """
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        try:
            packed = fcntl.ioctl(sock.fileno(), _SIOCGIFADDR, struct.pack("256s", interface.encode()[:15]))
        except OSError as err:
            raise ValueError(f"interface {interface!r} has no IPv4 address here: {err.strerror}") from err
    return socket.inet_ntoa(packed[20:24])


def two_host_profile(address: str) -> str:
    """A Fast DDS profiles file: UDPv4 only, on the interface with IPv4 `address` only.

    Same participant announcements as the one-host profile (every 0.25 s); reliable writers' heartbeats
    every 0.1 s, so that a sample lost on the link is asked for again within a tenth of a second.
    """
    return _profile(
        "fastdds_two_hosts.xml", {"@ADDRESS@": address, "@MAX_MESSAGE@": str(TWO_HOST_MAX_MESSAGE_BYTES)}
    )


def two_host_environment(environ: dict[str, str], address: str, directory: Path) -> dict[str, str]:
    """The environment of a node of a two-host graph.

    `environ` with the UDP-only profile for the interface with IPv4 `address` (written into `directory`)
    in place of any other, and discovery beyond loopback (unless the user named static peers, which then
    are the only peers besides this host).
    """
    profile = directory / "fastdds_two_hosts.xml"
    profile.write_text(two_host_profile(address))
    env = {k: v for k, v in environ.items() if k not in PROFILE_VARIABLES}
    env[profile_variable()] = str(profile)
    if not environ.get("ROS_STATIC_PEERS"):
        env["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "SUBNET"
    return env
