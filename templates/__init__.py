"""Data only: ready project files and report templates."""
