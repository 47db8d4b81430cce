"""``[allocate]``: the settings of ``tolsim allocate`` (issue 14). Being written."""


def parse_allocation(table, tolerances):
    """Read ``[allocate]`` (a ``tolsim.io.config._Table``) for the config's ``tolerances``."""
    raise table.error(None, "section: tolsim allocate is not available yet")
