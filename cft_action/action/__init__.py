# Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
"""The drop-in :class:`rclpy.action.ActionClient` (:mod:`.client`) and its parts.

``client.ActionClient`` is glue over one object per concern: the action's rcl entities
(``_action_entities``), the feedback filter and its intake (``_feedback_filter``,
``_feedback_intake``), the goals held until the filter has reached the server (``_held_goals``),
the goals kept after their result (``_finished_goals``), the status trim (``_goal_status``) and the
response filter (``_own_responses``). :mod:`.goal_filter` plans the goal-id expressions and needs
no ROS. The C the client loads is in ``cft_action/native/reader/``.
"""
