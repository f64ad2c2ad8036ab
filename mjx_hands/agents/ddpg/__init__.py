"""Deep deterministic policy gradient, jitted end to end over batched environments."""

from mjx_hands.agents.ddpg.train import DDPG, DDPGConfig, LearnerState, TrainerState

__all__ = ["DDPG", "DDPGConfig", "LearnerState", "TrainerState"]
