"""The path follower, split by job.

:mod:`~agents.follow.state` holds what the follower remembers between steps
(:class:`~agents.follow.state.FollowState`), what it is given each step and its parameters;
:mod:`~agents.follow.primitives` the commands and clearances its jobs share;
:mod:`~agents.follow.motion` the step itself (advance along the waypoints, turn in place onto a
lane, brake into stops, DWA, the give-up watchdog); :mod:`~agents.follow.escape` the escape
move out of dead ends and the idle robot's keeping clear; :mod:`~agents.follow.edge` the edge
pass along walls.
"""
