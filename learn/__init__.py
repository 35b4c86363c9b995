"""learn: compensators from the four papers and beyond (planned; reads recordings through sensors, never MuJoCo)."""
