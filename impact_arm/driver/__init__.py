"""The simulated driver, free of ROS: the arm as its driver sees it (``arm``), the loop that
paces its periods (``realtime``), the simulator node's behaviour behind one interface
(``session``) and the controller's input handling (``control_inputs``). Built on ``physics``."""

# its modules are imported by name: the package itself exports none
__all__: list[str] = []
