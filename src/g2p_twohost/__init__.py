"""Two hosts on one machine, for tests and benchmarks of the graph split over a rig and a workstation.

`hosts.TwoHosts` builds a "rig" and a "workstation" network namespace joined by a user-space TUN link
(`forwarder`) that adds delay, jitter, loss and partitions; `graph.TwoHostGraph` starts the G2P graph of a
checkout on them, each side the way a user starts it on a Pi and a workstation. Standard library only;
it needs root (CAP_NET_ADMIN) and /dev/net/tun.
"""
