from .controller import main

raise SystemExit(main())
