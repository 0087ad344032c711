"""When to stop: the policies and wrappers that decide when pushing ends.

``stop_policy`` is the "no manipulation" system (it stops at once, I_stop = I_start); ``stop_margin`` lets a greedy Q
policy stop only when Q(stop) beats its best push by a margin; ``learned_stop`` stops when a critic fitted on the
policy's own episodes (``recipes/fit_stop.py``) predicts that pushing on no longer uncovers the targets, reading the
push network's maps and, when fitted so, the counting perception's count of the asked class
(``modules.answering.perceived_count``). ``q_override`` is what the two wrappers share to overrule the greedy choice:
the best allowed push, and writing the action taken with its Q value."""
