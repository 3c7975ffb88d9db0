# Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
"""Content-filtered subscriptions and what the topic tools share.

- :mod:`.subscription`: ``create_filtered_subscription`` and the filter calls on a subscription;
- ``_filtered_reader``: the one state machine of a content-filtered reader, which the action
  client, the parameter-event handler and the subscriptions all drive;
- :mod:`.arrival`: proof that a reader's filter has reached the remote writers;
- :mod:`.filters` and :mod:`.sql`: DDS-SQL expressions, their literals, and an evaluator of them
  (no ROS needed);
- :mod:`.message_types`, :mod:`.message_yaml` and :mod:`.topic_api`: message introspection and
  what the ``cft-action topic`` verbs share.
"""
