"""Command-line interface. Every module in this package with a ``register(subparsers)`` function
contributes its subcommands; see :mod:`skidsteer_power.cli.main`."""
