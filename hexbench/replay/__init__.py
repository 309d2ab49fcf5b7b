"""Tools that replay a run from its logs: verification, Minari export, .rrd from MCAP."""
