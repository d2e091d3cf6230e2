"""Shared leaves every room may import (they import nothing of the project above them):
provenance (software versions, JSON-safe records) and run-time defaults."""
