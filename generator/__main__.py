"""``python -m cmmwb.generator`` (anywhere) and ``python -m generator`` (in a checkout): the command line."""

from cmmwb.generator.cli import main

raise SystemExit(main())
