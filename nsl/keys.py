"""Feature and batch keys, shared by the dataset format, the loader and the learner.

They follow LeRobot's conventions (``observation.*``, ``action``, ``next.*``).
Learner and loader code uses these names, never string literals.
"""

OBS_IMAGE = "observation.image"  # (H, W, 3) uint8 camera frame
OBS_STATE = "observation.state"  # (STATE_DIM,) float32: see STATE_NAMES
ACTION = "action"  # (ACTION_DIM,) float32: dx, dy, dz, dyaw, close, terminate in [-1, 1]
REWARD = "next.reward"  # float32: 1 on the step that lifts an object
DONE = "next.done"  # bool: the episode terminated (not a time-limit truncation)
SUCCESS = "next.success"  # bool: the episode's grasp succeeded (on its last frame)
TRUNCATED = "next.truncated"  # bool: the episode hit its time limit without terminating

EPISODE_INDEX = "episode_index"
FRAME_INDEX = "frame_index"
INDEX = "index"
TIMESTAMP = "timestamp"
TASK_INDEX = "task_index"

# Transition batches produced by the training loader.
NEXT_OBS_IMAGE = "next.observation.image"
NEXT_OBS_STATE = "next.observation.state"
DISCOUNT = "next.discount"  # float32: gamma^k for a k-step transition (present only in n-step batches)

STATE_NAMES = ["gripper_opening", "wrist_height", "wrist_x", "wrist_y", "wrist_sin_yaw", "wrist_cos_yaw"]
ACTION_NAMES = ["dx", "dy", "dz", "dyaw", "close", "terminate"]
STATE_DIM = len(STATE_NAMES)  # length of OBS_STATE
ACTION_DIM = len(ACTION_NAMES)  # length of ACTION
FPS = 10  # nominal control rate recorded in dataset metadata (one frame per control step)
