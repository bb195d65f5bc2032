"""A two-host network bench on one machine: two network namespaces joined by an impairable TUN link."""
