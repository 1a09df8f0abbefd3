"""``python -m puppetcli``: the same as the ``puppetcli`` command."""

from puppetcli.daemon.client import main

main()
