"""Every tensordict key of mqa_rl, defined once. Import these instead of spelling strings.

The environment measures (observations and ``info``); reward transforms read ``info`` at the root
(state before a push) and under ``"next"`` (state after it).
"""

# observations
RGB = "rgb"                                   # uint8 [3, H, W]
DEPTH = "depth"                               # float32 [1, H, W], metres along the view axis
QUESTION = "question"                         # int64 [L], question tokens, 0-padded
ACTION = "action"                             # int64 [], push index or STOP
ACTION_MASK = "action_mask"                   # bool [NUM_ACTIONS] pushes whose start (from depth) is inside the bin, and stop
PUSHED = "pushed"                             # bool [NUM_PUSHES] pushes made this episode, with neighbours (PushMemory)
RESET_QUESTION = "reset_question"             # int64 [1] state (and observed, -1): the question index the next reset takes (-1 random)
REWARD = "reward"

# measurements of the scene (padded to MAX_OBJECTS, see OBJECT_MASK)
INFO = "info"
OBJECT_POS = (INFO, "object_pos")             # float32 [K, 3] world positions (bounding-box centres)
VISIBLE_AREA = (INFO, "visible_area")         # float32 [K] A_s: pixels of the object in the segmentation
FULL_AREA = (INFO, "full_area")               # float32 [K] A_t: pixels of its complete silhouette
OVERLAP = (INFO, "overlap")                   # float32 [K] χ = 1 − A_s / A_t (1 when A_t = 0)
OBJECT_MASK = (INFO, "object_mask")           # bool [K] which slots hold an object
TARGET_MASK = (INFO, "target_mask")           # bool [K] objects of the question's class(es)
IS_STOP = (INFO, "is_stop")                   # bool [1] the action that led here was stop
PUSH_START = (INFO, "push_start")             # float32 [3] executed push start (world), 0 if none
PUSH_END = (INFO, "push_end")                 # float32 [3] executed push end (world), 0 if none
QUESTION_INDEX = (INFO, "question_index")     # int64 [1] index into MQADataset.questions
ANSWER = (INFO, "answer")                     # int64 [1] index into MQADataset.answers (oracle)
PUSH_COUNT = (INFO, "push_count")             # int64 [1] pushes so far in the episode
QUESTION_TYPE = (INFO, "question_type")       # int64 [1] index into mqa_rl.data.questions.QUESTION_TYPES
# how the pusher executed the last push (the finger always reaches, touches nothing else, tracks exactly)
PUSH_UNREACHABLE = (INFO, "push_unreachable")  # bool [1] part of the push was out of the arm's reach (cut short or skipped)
ARM_COLLISION = (INFO, "arm_collision")        # bool [1] a robot part other than the pushing tool touched something
TIP_ERROR = (INFO, "tip_error")                # float32 [2] mean, max distance (m) of the tool tip from the push line
# the simulator's segmentation on the action grid: never a policy input, a training signal (auxiliary loss)
TARGET_CELLS = (INFO, "target_cells")          # float32 [GRID, GRID] fraction of each grid cell's pixels showing a target

# reward terms written by mqa_rl.transforms (under "next"; zeros after a reset), each float32 [1]
REWARD_TERMS = "reward_terms"
EXPLORATION = (REWARD_TERMS, "exploration")           # R_e
GLOBAL_OCCLUSION = (REWARD_TERMS, "global_occlusion")  # R_g
LOCAL_OCCLUSION = (REWARD_TERMS, "local_occlusion")    # R_l
SCENE_OCCLUSION = (REWARD_TERMS, "scene_occlusion")    # R_s: R_g over every object (question-agnostic)
COUNTABLE_TARGETS = (REWARD_TERMS, "countable_targets")  # R_c: targets made countable − buried, over the targets
SIMPLE_SCENE = (REWARD_TERMS, "simple_scene")          # 1.0 when the scene before the action was simple
BETA = (REWARD_TERMS, "beta")                          # β used for this step

# written by the Q-network policy (mqa_rl.modules.push) and its stops (mqa_rl.modules.stop), read by the DQN loss and
# the logs
ACTION_VALUE = "action_value"                 # float32 [NUM_ACTIONS] Q(s, ·), masked actions at the dtype's min
CHOSEN_ACTION_VALUE = "chosen_action_value"   # float32 [1] Q(s, a) of the chosen action
TD_ERROR = "td_error"                         # float32 [1] squared TD error, the replay priority
PERCEIVED_READING = "perceived_reading"       # float32 [len(READING)] a perceiving stop's reading of the state's frame

# running episode statistics (mqa_rl.transforms.episode_stats), observations read at episode ends
EPISODE = "episode"
EPISODE_REWARD = (EPISODE, "reward")                   # float32 [1] sum of rewards so far
EPISODE_TERMS = (EPISODE, "terms")                     # float32 [1] each: sums of the reward terms so far
TARGET_CHI_START = (EPISODE, "target_chi_start")       # float32 [1] mean target χ at reset (0 without target)
TARGETS_IN_VIEW_START = (EPISODE, "targets_in_view_start")  # bool [K] targets a counter sees at reset (≥ COUNTABLE_PX)

# one answering episode (mqa_rl.collectors.rollouts): what the VQA reads and what the reports need,
# stored per episode in a memmap TensorDict; FIRST / LAST hold the images I_start / I_stop
SLOT = "slot"                                 # int64 [] position in the collection plan (unique: the resume key)
QUESTION_ID = "question_index"                # int64 [] index into MQADataset.questions
ANSWER_LABEL = "answer_label"                 # int64 [] index into MQADataset.answers (the oracle answer)
TYPE_LABEL = "type_label"                     # int64 [] index into mqa_rl.data.questions.QUESTION_TYPES
LEVEL = "level"                               # int64 [] index into mqa_rl.data.dataset.LEVELS
SCENE = "scene"                               # int64 [] index into MQADataset.scenes
REPEAT = "repeat"                             # int64 [] which rollout of this question (0, 1, ...)
PUSHES = "pushes"                             # int64 [] pushes executed
STOPPED = "stopped"                           # bool [] the policy stopped (else the push budget ended the episode)
EPISODE_TARGETS = "target_mask"               # bool [K] objects of the question's class(es)
CHI_START = "chi_start"                       # float32 [] mean χ of the targets on I_start (NaN without target)
CHI_END = "chi_end"                           # float32 [] the same on I_stop
FIRST = "first"
LAST = "last"
FIRST_RGB = (FIRST, RGB)                      # uint8 [3, H, W] I_start
LAST_RGB = (LAST, RGB)                        # uint8 [3, H, W] I_stop
ANSWER_RGB = "answer_rgb"                     # uint8 [3, S, S] the env's answer camera (answer_size px): under FIRST / LAST in rollouts with one; in the observation with answer_observation=True
FIRST_ANSWER_RGB = (FIRST, ANSWER_RGB)
LAST_ANSWER_RGB = (LAST, ANSWER_RGB)
FIRST_DEPTH = (FIRST, DEPTH)                  # float16 [1, H, W] metres
LAST_DEPTH = (LAST, DEPTH)
FRAME_OVERLAP = "overlap"                     # under FIRST / LAST: float32 [K] χ of every object
FRAME_VISIBLE = "visible_area"                # under FIRST / LAST: float32 [K] A_s
FRAME_FULL = "full_area"                      # under FIRST / LAST: float32 [K] A_t
OBJECT_MAP = "object_map"                     # under FIRST / LAST: uint8 [H, W] 0 = bin, 1 + the object's slot (scene order)
CLASS_MAP = "class_map"                       # pretraining frames: uint8 [H, W] 0 = bin, 1 + index into MQADataset.classes
SLOT_AREA = "slot_area"                       # perception crops: float32 [50] pixels of each slot in the uncropped object map
OBJECT_CLASSES = "object_classes"               # perception frames: int64 [K] 1 + index into MQADataset.classes of each scene slot, 0 = empty
CLASS_CELLS = "class_cells"                   # push-trunk pretraining frames: float16 [1 + classes, GRID, GRID] class fractions per action-grid cell (SapienBinEnv.class_cells)

# the VQA (mqa_rl.modules.answering.vqa) and its loss (mqa_rl.losses.vqa)
FIRST_FEATURES = (FIRST, "features")          # float [C, h, w] VQAModel.encode_frames(I_start), cached when frozen
LAST_FEATURES = (LAST, "features")
ANSWER_LOGITS = "answer_logits"               # float32 [n_answers]
FRAME_ATTENTION = "frame_attention"           # float32 [2] attention over (I_start, I_stop), sums to 1
QUESTION_CLASSES = "question_classes"         # int64 [2] the classes a question names, 1 + index into MQADataset.classes (the encoder's class channels); -1 where it names fewer
GROUNDING_LOGITS = "grounding_logits"         # float32 [heads, 1 + classes] the classes pool's choice of class per head (VQAModel.grounding_logits)
