"""The vehicle's inner loop as the offboard controller models it: a virtual control
(ENU acceleration) to an attitude and thrust setpoint, and the first-order attitude and
thrust lags that realise it. Below both the agents, which command through it, and the
safety filter, which predicts with it.

* :mod:`.attitude` - :class:`~offboard.inner_loop.attitude.InnerLoopModel`, the setpoint
  conversion and clipping.
* :mod:`.attitude_kernel` - their compiled steps.
"""
