"""Tests of g2p_twohost: two network namespaces on one machine, joined by an impairable TUN link."""
