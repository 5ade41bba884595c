"""hdid design: candidate experiments ranked by the standard errors they would give (private)."""
