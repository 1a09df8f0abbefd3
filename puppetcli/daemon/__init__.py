"""A warm puppetcli process that runs commands for the ``puppetcli`` executable.

Starting Python, numpy and numba and loading the compiled solver from numba's cache
takes 1.5-2 s; a run of an example script takes a tenth of that.  After a run on the
compiled solver, puppetcli leaves a daemon behind (``serve``): a process that has
imported everything and loaded the solver, and forks a copy of itself for each later
command, with the command's arguments, working folder, environment and terminal
(``client``).  The fork runs the same code on the same inputs as a fresh process would,
so its outputs are the same bytes.

Each daemon serves one installation in one environment (``address``): an edit of the
sources, a package installed or removed, or another interpreter or environment
variable that changes a run makes a new one.  A daemon exits after ``IDLE`` seconds
without a command.  ``PUPPETCLI_DAEMON=off`` runs every command in its own process
and never starts a daemon; ``puppetcli daemon status|stop`` shows or stops them.
"""
