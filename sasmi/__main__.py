"""`python -m sasmi ...` runs the `sasmi` command."""
import sys

from sasmi.cli import main

sys.exit(main())
