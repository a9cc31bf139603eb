"""``python -m gravsurvey`` = the ``gravsurvey`` console script."""

from .cli import main

main()
