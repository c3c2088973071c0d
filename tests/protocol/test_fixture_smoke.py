from protocol.messages import RobotPose
from tests.conftest import TestClient, wait_for_message


def test_two_clients_exchange_a_pose_through_the_router(router, namespace, client):
    other = TestClient(namespace, router).open()
    try:
        q = client.collect(client.keys.robot_pose("*"), RobotPose)
        import time

        time.sleep(0.3)
        other.publish(other.keys.robot_pose("r0"), RobotPose(robot="r0", x=1.0, y=2.0, theta=0.1))
        msg = wait_for_message(q, lambda m: m.robot == "r0")
        assert (msg.x, msg.y, msg.src) == (1.0, 2.0, other.src)
        assert msg.seq == 1
    finally:
        other.close()
