from orccadd.cmdd.server import main

raise SystemExit(main())
