"""Recordings on disk: the canonical format of CONTRACT.md, atomic writers, importers of other formats."""
