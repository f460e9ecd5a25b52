"""The EM and its steps: Algorithm 1, the robust loop, the likelihood, the gate."""
