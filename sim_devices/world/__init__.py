"""The physics world: a scene simulated in MuJoCo, with device signals and ground truth."""
from .reality import ALL_DIFFERENCES, DIFFERENCES, JOINT_DIFFERENCES, Reality, with_reality
from .scenarios import SCENARIOS, ScenarioInfo, build_scenario
from .trajectory import Hold, PointToPoint, Sinusoid, Trajectory
from .truth import TruthWriter, truth_record
from .world import ContactTruth, Obstacle, Probe, ScenarioSetup, World, WorldState

__all__ = ["ALL_DIFFERENCES", "DIFFERENCES", "JOINT_DIFFERENCES", "SCENARIOS", "ContactTruth", "Hold", "Obstacle",
           "PointToPoint", "Probe", "Reality", "ScenarioInfo", "ScenarioSetup", "Sinusoid", "Trajectory",
           "TruthWriter", "World", "WorldState", "build_scenario", "truth_record", "with_reality"]
