"""``python -m fleet.cli ...``: how the launcher, compose.yaml and the tests run a command."""

from fleet.cli import main

main()
