"""The loop that runs the force path at 1 kHz: clocks, the loop and its messages, the watchdog and the dead-loop
supervisor, the tick record and the shared-memory ring, and the engine that assembles rig, framework and loop."""
