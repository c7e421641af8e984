"""Plan stage: CheckedScene -> Plan (typed data: buffers, groups, the calls of a step)."""
