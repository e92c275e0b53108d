"""recorder_node with a loss injected, for the tests of what a loss does to a run.

``python -m lossy_recorder --ros-args ...`` (tests/ on PYTHONPATH) runs the package's
recorder_node, except that every correction after the first ``GRAZING_TEST_KEEP``
(default 40) is taken from the middleware and not recorded: the tail of the topic is
lost as it was when the recorder was stopped before it had taken them (issue 27). The
recorder's own check must find it.
"""

import os
import sys

from grazing_control.ros import recorder_node

KEEP = int(os.environ.get("GRAZING_TEST_KEEP", "40"))
_record = recorder_node.RecorderNode._record


def _lossy_record(self, topic, data, info):
    if topic.endswith("/controller/velocity_correction"):
        self._kept = getattr(self, "_kept", 0) + 1
        if self._kept > KEEP:
            return
    _record(self, topic, data, info)


recorder_node.RecorderNode._record = _lossy_record

if __name__ == "__main__":
    sys.exit(recorder_node.main())
