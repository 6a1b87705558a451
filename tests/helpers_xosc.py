"""Small OpenSCENARIO files of the tests' own, on the hand-made straight map (x along the road,
lanes -1..-3 of 3.5 m at y = -1.75, -5.25, -8.75): the pieces the OpenSCENARIO import tests
(tests/converters/test_openscenario*.py) write them from."""

from __future__ import annotations

import pyarrow.compute as pc
from helpers_common import STRAIGHT_MAP

CAR = """<Vehicle name="car" vehicleCategory="car"><BoundingBox><Center x="{cx}" y="0" z="0.7"/>
<Dimensions width="1.8" length="4.5" height="1.4"/></BoundingBox></Vehicle>"""


def xosc(tmp_path, entities: str, init: str, story: str = "", params: str = "",
         stop: str = "", name: str = "s.xosc"):
    text = f"""<?xml version="1.0"?>
<OpenSCENARIO><FileHeader revMajor="1" revMinor="2" date="2026-01-01T00:00:00" description="t" author="me"/>
<ParameterDeclarations>{params}</ParameterDeclarations>
<CatalogLocations/><RoadNetwork><LogicFile filepath="map.xodr"/></RoadNetwork>
<Entities>{entities}</Entities>
<Storyboard><Init><Actions>{init}</Actions></Init>{story}<StopTrigger>{stop}</StopTrigger></Storyboard>
</OpenSCENARIO>"""
    (tmp_path / "map.xodr").write_bytes(STRAIGHT_MAP.read_bytes())
    p = tmp_path / name
    p.write_text(text)
    return p


def ent(name: str, cx: float = 0.0) -> str:
    return f'<ScenarioObject name="{name}">{CAR.format(cx=cx)}</ScenarioObject>'


def teleport(name: str, pos: str, speed: float | str | None = None) -> str:
    sp = "" if speed is None else f"""<PrivateAction><LongitudinalAction><SpeedAction>
<SpeedActionDynamics dynamicsShape="step" dynamicsDimension="time" value="0"/>
<SpeedActionTarget><AbsoluteTargetSpeed value="{speed}"/></SpeedActionTarget></SpeedAction>
</LongitudinalAction></PrivateAction>"""
    return (f'<Private entityRef="{name}"><PrivateAction><TeleportAction><Position>{pos}'
            f"</Position></TeleportAction></PrivateAction>{sp}</Private>")


def follow(shape: str, timing: str = "<None/>", extra: str = "") -> str:
    return f"""<PrivateAction><RoutingAction><FollowTrajectoryAction {extra}><TrajectoryRef>
<Trajectory name="tr" closed="false"><Shape>{shape}</Shape></Trajectory></TrajectoryRef>
<TimeReference>{timing}</TimeReference><TrajectoryFollowingMode followingMode="position"/>
</FollowTrajectoryAction></RoutingAction></PrivateAction>"""


def poly(*vertices: str) -> str:
    return "<Polyline>" + "".join(vertices) + "</Polyline>"


def vertex(x, y, t=None, h=None) -> str:
    at = "" if t is None else f' time="{t}"'
    hh = "" if h is None else f' h="{h}"'
    return f'<Vertex{at}><Position><WorldPosition x="{x}" y="{y}"{hh}/></Position></Vertex>'


def story(events: str, actor: str = "A") -> str:
    return f"""<Story name="s"><Act name="act"><ManeuverGroup maximumExecutionCount="1" name="mg">
<Actors selectTriggeringEntities="false"><EntityRef entityRef="{actor}"/></Actors>
<Maneuver name="m">{events}</Maneuver></ManeuverGroup></Act></Story>"""


def event(name: str, actions: str | list[str], trigger: str = "") -> str:
    trig = f"<StartTrigger><ConditionGroup>{trigger}</ConditionGroup></StartTrigger>" if trigger else ""
    acts = "".join(f'<Action name="{name}_{k}">{a}</Action>'
                   for k, a in enumerate([actions] if isinstance(actions, str) else actions))
    return f'<Event name="{name}" priority="override">{acts}{trig}</Event>'


def sim_time(v, delay=0) -> str:
    return (f'<Condition name="c" delay="{delay}" conditionEdge="rising"><ByValueCondition>'
            f'<SimulationTimeCondition value="{v}" rule="greaterThan"/></ByValueCondition></Condition>')


def states_of(rec, pid=0):
    s = rec.states.filter(pc.equal(rec.states["participant_id"], pid))
    return {c: s[c].to_numpy() for c in ("time", "x", "y", "heading")}
