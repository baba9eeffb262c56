"""Toy extensions used by tests/test_registries.py: each is one module plus one registry entry."""
