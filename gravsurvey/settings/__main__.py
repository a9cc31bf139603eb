"""``python -m gravsurvey.settings --doc``: regenerate docs/config.md's key reference."""

from .reference import main

raise SystemExit(main())
