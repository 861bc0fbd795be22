"""``python -m generator`` (in a checkout) and ``python -m cmmwb.generator``: the command line."""

from cmmwb.generator.cli import main

raise SystemExit(main())
