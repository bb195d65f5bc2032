"""Bring-up of the G2P graph."""
