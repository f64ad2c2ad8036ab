"""Train a hand-interaction policy: the project's single command.

    python train.py --task handshake            # the project's setup (ddpg-ln), by device
    python train.py --task et --profile paper   # the authors' environment and DDPG
    python train.py --task handclap --algo ddpg-ln  # with LayerNorm (the evidence's pick)
    python train.py --task et --no-imitation    # an ablation
    python train.py --run-dir runs/x --resume   # continue a run with its own config
    python train.py --run-dir runs/x --resume --epochs 400   # ... and a larger budget

Everything written goes to the run directory: config.json, metrics.csv, TensorBoard
events (``tensorboard --logdir runs``), Orbax checkpoints and success.png.
``python -m mjx_hands.evaluate RUN_DIR`` reloads the policy and renders a video.
"""

from mjx_hands.train_cli import main

if __name__ == "__main__":
    raise SystemExit(main())
