"""The contact profile of a batch of episodes: which sensors touched the other hand,
when, and how many of a task's required ones at once.

The paper judges an interaction by its contact profile; success (all required sensors
in contact at the same step) is one number of it. These are host-side NumPy functions
over recorded sensor readings, shared by ``mjx_hands.evaluate`` (learned policies)
and ``mjx_hands.demo_replay`` (the scripted demonstration follower).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from mjx_hands import shadow_hand


def summarize(contacts: np.ndarray, groups: np.ndarray) -> dict:
    """JSON-ready contact profile.

    Args:
      contacts: (T, n, 15) sensor readings (0/1) of n episodes over T control steps, in
        ``shadow_hand.CONTACT_SENSORS`` order.
      groups: (G, 15) bool, the task's success groups (one sensor of each must touch;
        empty rows are ignored), or (15,) required sensors that must all touch.
    Returns:
      ``touched``: per sensor, the fraction of episodes in which it touched at some step;
      ``in_contact``: per sensor, the fraction of episode steps in contact;
      ``required``: names of the required sensors; ``groups``: names per group;
      ``all_required_over_time``: (T,) fraction of episodes with every group satisfied
      at that step;
      ``episodes_by_required_at_once``: histogram over episodes of the most groups
      satisfied at one step (index k: episodes whose best step had k);
      ``success``: fraction of episodes with every group satisfied at some step;
      ``success_final``: ... at the last step (the authors' metric).
    """
    contacts = np.asarray(contacts) > 0.5
    groups = np.asarray(groups, bool)
    names = shadow_hand.CONTACT_SENSORS
    if groups.ndim == 1:
        groups = np.diag(groups)
    if contacts.ndim != 3 or contacts.shape[-1] != len(names) or groups.shape[-1] != len(names):
        raise ValueError(
            f"expected contacts (T, n, {len(names)}) and groups (G, {len(names)}), "
            f"got {contacts.shape} and {groups.shape}"
        )
    groups = groups[groups.any(-1)]
    satisfied = (contacts[..., None, :] & groups).any(-1)  # (T, n, G)
    at_once = satisfied.sum(-1)  # (T, n)
    all_required = at_once == len(groups)
    return {
        "touched": dict(zip(names, contacts.any(0).mean(0).tolist(), strict=True)),
        "in_contact": dict(zip(names, contacts.mean((0, 1)).tolist(), strict=True)),
        "required": [n for n, r in zip(names, groups.any(0), strict=True) if r],
        "groups": [[n for n, r in zip(names, g, strict=True) if r] for g in groups],
        "all_required_over_time": all_required.mean(1).tolist(),
        "episodes_by_required_at_once": np.bincount(
            at_once.max(0), minlength=len(groups) + 1
        ).tolist(),
        "success": float(all_required.any(0).mean()),
        "success_final": float(all_required[-1].mean()),
    }


def over_time(contacts: np.ndarray) -> np.ndarray:
    """(15, T) share of episodes with each sensor in contact per step; contacts (T, n, 15)."""
    return (np.asarray(contacts) > 0.5).mean(1).T


def plot(contacts: np.ndarray, profile: dict, path: Path, title: str, dt: float) -> None:
    """PNG of the profile: each sensor's share of episodes in contact over time (required
    sensors starred), and below it the share with all required sensors at once.

    contacts: (T, n, 15) readings; profile: :func:`summarize` of them; dt: control period (s).
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    share = over_time(contacts)
    steps = share.shape[1]
    extent = (0.0, steps * dt, len(shadow_hand.CONTACT_SENSORS) - 0.5, -0.5)
    fig, (top, bottom) = plt.subplots(
        2, 1, figsize=(8, 6), sharex=True, layout="constrained", height_ratios=[3, 1]
    )
    image = top.imshow(share, aspect="auto", cmap="viridis", vmin=0, vmax=1, extent=extent)
    labels = [
        f"{name} *" if name in profile["required"] else name for name in shadow_hand.CONTACT_SENSORS
    ]
    top.set_yticks(range(len(labels)), labels, fontsize=8)
    top.set_title(f"{title}: share of episodes in contact (* required)")
    fig.colorbar(image, ax=(top, bottom), fraction=0.04, pad=0.01)
    time = (np.arange(steps) + 1) * dt
    bottom.plot(time, profile["all_required_over_time"], color="tab:red")
    bottom.set_ylim(0, 1.02)
    bottom.set_ylabel("all required")
    bottom.set_xlabel("time in episode (s)")
    bottom.grid(alpha=0.3)
    fig.savefig(path, dpi=110)
    plt.close(fig)
