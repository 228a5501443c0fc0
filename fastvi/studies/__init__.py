"""Reproducible studies behind the docs: each module is the single source of a table or figure."""
