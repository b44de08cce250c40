"""Test and demo helpers that speak real protocols on loopback (never imported by the library itself)."""
