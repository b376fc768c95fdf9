"""`python -m sasmi ...` runs the `sasmi` command."""
import sys

from sasmi.cli.main import main

if __name__ == "__main__":  # not when a process that `render --workers` or `generate --workers` spawns imports it
    sys.exit(main())
