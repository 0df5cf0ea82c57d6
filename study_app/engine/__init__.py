"""The study engine process: the typed messages between GUI and engine, the host that runs the loop and the
sessions, the client the GUI drives it with, the engine's set-up and the commissioning steps."""
