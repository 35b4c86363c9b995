"""Compensators, training, metrics, checkpoints and paper experiments.

`learn` reads recordings through `sensors` (never MuJoCo) and maps what the instrument reports
(e.g. `resistance_measured`) to the ground truth (e.g. `force`).

  learn.data         episodes -> in-memory sequences, stratified splits, dataset hashes
  learn.metrics      MAE, RMSE, R^2, MSE, R, mean relative error, hysteresis error % FSO
  learn.train        seeded Adam loop with early stopping and a progress bar
  learn.checkpoint   config.json + model.safetensors (never pickled)
  learn.models       the compensator registry (linear, cubic, mlp, gru, lstm, tcn, ...)
  learn.experiments  one module per paper (cnt_pdms, ...), registered by name
"""
