from ttes.cli import main

raise SystemExit(main())
