"""``python -m grazing_control.cli``: the ``grazing`` command."""

from .commands import main

raise SystemExit(main())
