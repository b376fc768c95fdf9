"""Scenes: frozen dataclasses (model), the TOML presets that draw them (preset), their values (values)."""
