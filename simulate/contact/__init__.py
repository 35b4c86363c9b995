"""The contact stage: scene -> MJCF, MuJoCo (C or Warp) episodes -> per-taxel load field, press-stroke contacts."""
