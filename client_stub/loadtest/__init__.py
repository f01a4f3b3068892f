"""The load generator (`ttes loadtest`): sessions of link clients, the realistic mix, statistics, plots."""
