"""``python -m cmmwb``: the command line (the same as the console script ``cmmwb``)."""

from cmmwb.generator.cli import main

raise SystemExit(main())
