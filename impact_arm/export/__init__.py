"""The arm and its calibrated contact, exported to the simulators users already run
(MuJoCo, Drake, Gazebo): the peers' model files, the contact parameters fitted by running
each peer through the same strikes as the package's model, and the residual each leaves
(docs/export.md). Plain Python: no ROS, and each peer imported only when it is used."""

from .exporter import export
from .peers import Peer
from .report import PeerReport

__all__ = ['Peer', 'PeerReport', 'export']
