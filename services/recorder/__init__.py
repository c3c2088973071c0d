"""Recordings of a run: ``arroch record`` (MCAP, Foxglove or ROS 2 messages), ``arroch view`` (the same
channels live on the Foxglove WebSocket protocol), ``arroch replay`` (a recording back onto Zenoh) and
``arroch runs show`` (a run's summary and timeline)."""
