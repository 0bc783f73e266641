"""Command-line interface (thin)."""
