"""`python -m landscape.client.cli`: the same as the `landscape` console script."""
from landscape.client.cli.app import main

main()
