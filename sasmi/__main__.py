"""`python -m sasmi ...` runs the `sasmi` command."""
import sys

from sasmi.cli.main import main

sys.exit(main())
