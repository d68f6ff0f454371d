"""``python -m app.cli``: the ``deltadash`` command without the installed script."""

from app.cli import main

raise SystemExit(main())
