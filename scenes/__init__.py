"""The shipped scene presets (TOML files beside this file), installed as `sasmi.scenes`."""
