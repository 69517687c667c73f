"""``impact-arm analyze FILE.mcap [--out DIR]``: impact table, limit cycle, Poincaré sections,
the article's figures and a markdown report, from a recording alone (no rclpy; CDR is decoded
by ``rosbags``' typestore for ROS 2 Kilted: speed does not matter here, and it is the
reference decoder the tests already trust; ``io/wire.py`` stays the hot path's codec).

What is read (docs/topics.md): ``/joint_states`` (relative joint angles → absolute link angles
q1, q2 = joint1 + joint2 and their rates; time = header stamp), ``/impact_report`` (one JSON
impact record each: the table is exactly the one ``simulate`` prints), ``/impact_trace``
(full-resolution points inside each impact: Figures 8–11), and the scene stored in the file
(link lengths for the tip velocity of Figure 7, the controller law for Figure 3).

Outputs in DIR (default: ``runs/<FILE name without .mcap>_analysis``): ``report.md``,
``impacts.json`` (``{"impacts": [...]}``, the records as published), ``impact_table.txt``,
``poincare_qd1_zero.csv`` … ``poincare_qdN_zero.csv`` (one per link) and the figures
``fig3_controllers.png`` … ``fig11_kinetic_energy.png`` (``figures.FIGURE_SIZE`` pixels
each; ``--format svg|pdf``, ``--dpi``). The impact table and the limit cycle are printed
before any figure is drawn; the animation is a step of its own (``impact-arm animate``, or
``--animation``). Figure 3 is the article's comparison of the control laws (``--laws``,
default q, pd, pid): step responses of the file's scene with its surface taken away,
simulated offline. Figures 8-11 come from ``/impact_trace`` (offline recordings) or, in a
live recording, from the impact integrated again from its ``/impact_report`` contact state
(exact when the actuators are off during contact, as in the article; beyond two links the
joint rates at contact are those that give the reported tip velocity and link energies);
when neither is possible the command says why. Figures 4-6 and 11 draw every link of the
arm.

The package: ``impacts`` (each impact at full resolution), ``sections`` (limit cycle, Poincaré
sections, impact table), ``report`` (what is written) and ``command`` (the command line); the
recording is read by ``tools/run_data.py``, the step responses of Figure 3 come from
``tools/step_responses.py``.
"""

from ..run_data import AnalysisError, Run, chatter, load
from ..step_responses import step_response
from .command import add_arguments, cli
from .impacts import elastic_curve, impact_points, reintegrated_trace
from .report import recording_origin, write_outputs
from .sections import impact_table, limit_cycle, poincare, tip_velocity

__all__ = [
    'AnalysisError',
    'Run',
    'add_arguments',
    'chatter',
    'cli',
    'elastic_curve',
    'impact_points',
    'impact_table',
    'limit_cycle',
    'load',
    'poincare',
    'recording_origin',
    'reintegrated_trace',
    'step_response',
    'tip_velocity',
    'write_outputs',
]
