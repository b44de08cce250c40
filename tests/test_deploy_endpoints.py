"""A bad address given from Python (not only through the CLI) is a typed RTDEError, never a traceback."""

import pytest

from robocritics.deploy import DashboardClient, RTDEClient, send_program
from robocritics.errors import RTDEError

TOO_LONG_LABEL = "a" * 70  # DNS labels are at most 63 bytes: the idna codec raises UnicodeError


@pytest.mark.parametrize(
    "connect, where",
    [
        (lambda: RTDEClient(TOO_LONG_LABEL, 30004, timeout_s=0.5).connect(), "cannot connect to RTDE at"),
        (lambda: DashboardClient(TOO_LONG_LABEL, 29999, timeout_s=0.5).connect(), "cannot connect to the dashboard server at"),
        (lambda: send_program(TOO_LONG_LABEL, "def p():\n  sync()\nend\n", 30002, timeout_s=0.5), "cannot connect to the secondary interface at"),
    ],
)
def test_a_host_name_that_cannot_be_encoded_is_an_rtde_error(connect, where):
    with pytest.raises(RTDEError) as info:
        connect()
    assert str(info.value).startswith(f"{where} {TOO_LONG_LABEL}:")
    assert "label too long" in str(info.value)


def test_the_ur_arm_is_a_deploy_backend_and_a_stand_in_without_deploy_is_not():
    from robocritics.deploy import Backend, URArm

    assert isinstance(URArm("127.0.0.1"), Backend)  # not connected: the protocol is about what it offers

    class ReadOnly:
        def actual_q(self):
            return [0.0] * 6

    assert not isinstance(ReadOnly(), Backend)
