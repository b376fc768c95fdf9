"""The `sasmi` command: main parses and dispatches, arguments checks, one module per command."""
