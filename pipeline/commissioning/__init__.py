"""The commissioning maths: payload identification and its pose advice, the tool-centre-point calibration, the frame
check and the calibration file that stores their results. No device I/O: the steps that move the robot are
:mod:`study_app.engine.commissioning`."""
