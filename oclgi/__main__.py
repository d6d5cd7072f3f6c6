"""``python -m oclgi``: the command line (oclgi.cli), whose start-up handles
a Ctrl-C during its own imports."""

from .cli import main

raise SystemExit(main())
