"""Publish one screw to stiffness_node and print the stiffness K it answers with.

Run the node (`bash scripts/run_node.sh`), then in another shell:
`source scripts/env.sh && python examples/read_stiffness.py`.
"""

import threading
import time

import numpy as np
import rclpy
from rclpy.executors import SingleThreadedExecutor
from std_msgs.msg import Float64MultiArray

rclpy.init()
node = rclpy.create_node('stiffness_client')
got = threading.Event()


def on_stiffness(msg: Float64MultiArray) -> None:
    # K: rows [fx fy fz mx my mz], columns [wx wy wz vx vy vz]
    print(np.array(msg.data).reshape(6, 6))
    got.set()


node.create_subscription(Float64MultiArray, '/stiffness_node/stiffness', on_stiffness, 10)
pub = node.create_publisher(Float64MultiArray, '/stiffness_node/screw', 10)
executor = SingleThreadedExecutor()
executor.add_node(node)
spinner = threading.Thread(target=executor.spin, daemon=True)
spinner.start()
while pub.get_subscription_count() == 0:
    time.sleep(0.05)
pub.publish(Float64MultiArray(data=[2.2214, 0.0, -2.2214, 0.0167, 0.0, 0.0167]))
got.wait(5.0)
executor.shutdown()
spinner.join()
node.destroy_node()
rclpy.shutdown()
