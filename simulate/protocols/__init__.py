"""Loading protocols: what the indenter (or compression tester) is commanded to do, one random draw per episode."""
