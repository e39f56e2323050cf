"""Subcommands beyond ``info``; importing this module registers them with the CLI."""
