"""Motion profiles (pure): smooth set-point trajectories for the joints."""

from lolacli.motion.profile import back_and_forth, min_jerk

__all__ = ["back_and_forth", "min_jerk"]
