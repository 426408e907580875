"""Scene files (TOML): a whole run described in one file."""
