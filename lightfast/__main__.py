from lightfast.cli import main

raise SystemExit(main())
