# Copyright 2026 The cft_action authors. Licensed under the Apache License, Version 2.0.
"""The filtered :class:`rclpy.parameter_event_handler.ParameterEventHandler`
(:mod:`.parameter_events`) and the filter it keeps on ``/parameter_events``
(``_parameter_event_filter``)."""
