"""``python -m puppetcli``: the same as the ``puppetcli`` command."""

from puppetcli.cli import cli

cli(prog_name="puppetcli")
