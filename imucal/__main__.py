from imucal.cli.main import main

raise SystemExit(main())
