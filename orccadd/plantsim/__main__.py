from orccadd.plantsim.server import main

raise SystemExit(main())
