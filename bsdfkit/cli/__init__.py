"""``bsdfkit <verb>``: the command line, one module per verb, each a thin wrapper over the library."""
