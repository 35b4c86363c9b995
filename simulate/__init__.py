"""simulate: MuJoCo scenes, loading protocols, contact -> per-taxel load field."""
