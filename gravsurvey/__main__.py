"""``python -m gravsurvey`` = the ``gravsurvey`` console script."""

from .console import main

main()
