from nearsub.tools.cli import main

raise SystemExit(main())
