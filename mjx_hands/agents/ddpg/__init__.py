"""Deep deterministic policy gradient, jitted end to end over batched environments and
over a population of independent runs."""

from mjx_hands.agents.ddpg.learner import (
    DDPG,
    DDPGConfig,
    LearnerState,
    TrainerState,
    member,
    stack_members,
)

__all__ = ["DDPG", "DDPGConfig", "LearnerState", "TrainerState", "member", "stack_members"]
