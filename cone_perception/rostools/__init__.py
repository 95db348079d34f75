"""ROS tools that drive live node processes: the live replay (``replay --live``, ``demo``), the soak (``soak``) and
the fuzzer (``fuzz``). Like :mod:`cone_perception.nodes` they import rclpy; they sit above the nodes and the
tools they use (bench/, synth/, data/), so the nodes import none of them."""
