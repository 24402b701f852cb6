"""`python -m lightfast`: the command line (lightfast.cli)."""
from lightfast.cli import main

raise SystemExit(main())
