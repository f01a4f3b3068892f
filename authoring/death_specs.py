"""The seven deaths' specifications (:class:`DeathSpec`, :data:`DEATHS`): how each one goes, apart from
:mod:`authoring.deaths`, which simulates them, so that a module the death pipeline imports (``slave_feet``,
through ``contact_pin``) can ask what a death asks for without importing the pipeline back (issue 14)."""

from __future__ import annotations

from dataclasses import dataclass, replace

DEAD = "DEAD"
MAX_SECONDS = 6.0  # s: a death's physics records at most this long
TOSS = 40.0  # N: the hands fling the rifle they let go of (clear of the falling body)
TOSS_SECONDS = 0.1  # s: ... this long (deaths; rifle_drop, a let-go rifle recorded again alone)
REST_SPEED = 0.03  # m/s: a body (each body; the rifle alone) slower than this is still
REST_SECONDS = 0.35  # s: ... this long: the death is over (the rifle at rest)


@dataclass(frozen=True)
class DeathSpec:
    """How one death goes: the posture it starts from and the hit and slump that fell the soldier."""

    name: str  # the transition file, e.g. "ststow2dead"
    start: str  # its posture
    force: float  # N, peak of the hit on the upper torso
    direction: tuple[float, float, float]  # the hit's direction, pelvis heading frame (x right, z back)
    slump: str = "all"  # what slumps: "all" (the SLUMP key: knees buckle), "upper" (spine and head), "head"
    ramp: float = 0.15  # s, the hit ramps up (and down) this long
    hold: float = 0.25  # s, the hit is at its peak this long
    slump_time: float = 0.4  # s, the muscles reach the slumped shape (at slump_gain of their strength)
    slump_gain: float = 0.5
    fade: float = 1.0  # s, by then only a faint tone toward the limp shape is left
    release: float = 0.35  # s, the hands let go of the rifle
    sideways: bool = False  # he may come to rest on his side: the legs roll outward only if on his front
    knee_damping: float = 1.0  # the knees' damping is this many times stronger until he is down
    arm_tone: float = 0.0  # the fraction of the arms' gain kept when dead (toward the DEAD key's arms)
    toss: float = TOSS  # N, the hands fling the rifle they let go of this hard (he must not land on it)
    toss_to: tuple[float, float, float] | None = None  # the toss's direction in the pelvis' own frame (x
    # right, y up the spine, z back); None: to the side, away from the fall
    knee_straighten: float | None = None  # s, a standing death's knees start straightening (None: at fade)
    hip_damping: float = 1.0  # the hips', waist's and lower back's (FALL_STIFF) damping: this many times
    # stronger until he is down
    arms_fall: bool = False  # on his back, his arms fall to the ground after the physics (dead_settle)
    # cm: how far a fallen arm's forearm and hand may reach past his shoulders toward his head (dead_settle
    # _Arm.overhead; None: anywhere): half on his side, kfire2dead's top arm lay lowest curled over his head
    arms_headward_cm: float | None = None
    propped: bool = False  # prone, left propped on his elbows: the chest comes down after the physics
    legs_lift: bool = False  # kneeling: a leg part that would skid on the ground lifts instead (leg_lift)
    # the skid taken out so that each part's worst slide is least, not the mean drift (kfire2dead: the thigh
    # he lands on skids in the physics, 7.37 -> 3.92 cm; kstow2dead's thigh 4.51 -> 2.53 but then its arms'
    # fall slid the chest 5.87: planted.plant_least_worst)
    plant_worst: bool = False
    # frames (Gaussian sigma): the legs' change by the pins and the lift smoothed over the clip
    # (leg_lift.eased_legs): kstow2dead's right foot's pin stretched the knee as the leg came down and let
    # it go 19 degrees in a frame, its lift turned an ankle 10 degrees for one frame (flicks)
    legs_eased: float = 0.0
    # once his legs are lifted, he is shifted and turned about the vertical so that each part's worst slide
    # is least (kfire2dead's trunk, 3.3-3.7 cm: planted.least_worst_turned)
    turn_worst: bool = False
    # the turn measures the slides along the check's directions (body_parts.DIRECTIONS, 16), not the
    # planted.WORST_DIRECTIONS (8): kfire2dead's chest slid 3.007 cm (limit 3) where the turn saw 3.0
    turn_as_checked: bool = False
    # the slaves' trunk rest holds a foot near the ground whose knee is up where it was (slave_rest
    # feet_held): kfire2dead's DI, its trunk turned to rest, lowered its hovering right foot onto the ground
    # while it moved (skate 0.32 -> 4.06 cm once he was turned least-worst)
    slave_feet_held: bool = False
    # cm: how far the slaves' trunk rest may move a part resting on the ground (slave_rest; None: its
    # SLIDE_CM, 0.8): kfire2dead's DI pelvis, bridged between its belly and left thigh on the ground, came
    # down only to 2.34 cm (the check's rest limit 2) with the hands, knee, thigh and foot held to 0.8
    slave_rest_slide_cm: float | None = None
    # the slaves hold a foot where it is on the ground in each of the master's stances even where its knee
    # is down too (slave_feet.plant_slave_feet; else only in his last stance): kstow2dead's DI, its left knee
    # down, dragged that foot 9.5 cm (frames 52-64) once the master's right hip no longer flicked at frame 61
    # (the flick had lifted the whole DI 2-3 cm off the ground there, build.lift_off_ground)
    slave_feet_knelt: bool = False
    # the slaves' trunk rest holds an upper arm or forearm lying on the ground at the end where it lands
    # (slave_rest arms_held): prfire2dead's DI/M16, the trunk lowered under a right arm still swinging in,
    # touched down and swept it 3.8/4.2 cm along the ground
    slave_arms_held: bool = False
    pinned: bool = False  # after the settle, the limbs on the ground are held still (contact_pin)
    slave_arm_out: bool = False  # the DI slave's arms in the ground go out sideways (slave_ground.rest_limbs)
    # the slave's trunk is laid by its root alone (slave_ground.rest_limbs): with its spine in the torso's
    # goals, ststow2dead's DI belly asked 0.4 cm down moved 3 and the trunk swung (head slid 8.15 cm)
    slave_trunk_rigid: bool = False
    # the slave's feet are held where its own feet land in the master's last stance (slave_feet): laid by
    # the root alone, ststow2dead's DI trunk took its feet along after they landed (3.1 cm)
    slave_feet_landed: bool = False
    # the slave's hands and forearms on the ground keep their place and turn where they come to rest, last
    # (authoring.slave_arms): stfire2dead's DI left hand rolled under rest_limbs' frame-by-frame solve as its
    # trunk settled, its nodes sliding 4.0 cm where the master's lay still
    slave_arms_pinned: bool = False
    # frames: the slaves' neck and head keep their start posture's pose (the node's, which the build snaps
    # their first frame to) and blend into the solved fall over this many (authoring.build.snap_endpoints)
    slave_head_held: int = 0
    knees_held: bool = False  # after the settle, a knee on the ground stays put: the root follows it and the
    # legs keep their feet (knee_hold); a kneeling death's tucked right foot slid 9-10 cm instead
    # s: the hips and ankles roll out over this after :attr:`fade` into the dead legs' passive range
    # (:data:`PASSIVE_ROLL`, :mod:`authoring.passive_range`), while the legs still move as he lands; None:
    # to :data:`ROLLED_LEGS` over :data:`KNEE_STRAIGHTEN` (a crawler's thighs, rolled sooner, slid 6-8 cm)
    legs_roll: float | None = None
    # the settle lays the legs again as he lands (dead_settle.settle's ``legs``); False: they stay as
    # the physics laid them (ststow2dead, rolled as he landed: laid again, his right foot moved from 0.5 s
    # after he lay still, limb_rest_lag 1.13 s; stfire2dead keeps it: without, its heels rest 21.5 cm up)
    legs_settle: bool = True
    kept: tuple[tuple[str, float], ...] = ()  # joints (name suffix, until s) that keep the start posture's
    # shape at kept_tone of their gain, letting go over KEPT_FADE from then on
    kept_tone: float = 0.0
    # s: the recorded fall leaves its start posture from rest over this (authoring.easing.eased_in; 0: as
    # recorded). A prone death's first frames moved at 0.46 m/s (the toes leaving the ground, the hip) and
    # its DI/M16 slaves' at 0.57-0.67, over the check's end_speed
    start_ease: float = 0.0
    # a crawler's trunk comes down about his thighs after the physics, before the chest and head settle
    # (:func:`authoring.dead_crawl.sunk`): his kept arms held the pelvis and belly 4-5 cm up
    sunk: bool = False
    # a prone death's feet go slack after he has landed (issue 14: the ragdoll left him on his toes, heels
    # 16-21 cm up): the settle points the ankles into their passive range and straightens the knees before
    # the legs roll (:data:`authoring.dead_legs.FEET_LEADS`), the shins staying on the ground; after the
    # physics, on the figure with the legs' passive range (:mod:`authoring.passive_range`)
    slack_feet: bool = False
    # the slaves' ankles and toes take the master's angles as his feet go slack (authoring.slave_slack):
    # solved to his foot's points, crawl2dead's DI lay on its toes curled to their limit, heels 19.3 cm up
    slave_feet_slack: bool = False
    # a prone death's legs roll out one after the other as his chest comes down, the pelvis rolling a few
    # degrees with each (authoring.prone_roll): the settle left prstow/prfire on their toes, heels 20.2 cm up;
    # his slaves' trunks are lowered while his pelvis rolls in place (slave_ground._rolling_in_place)
    prone_legs_roll: bool = False
    # N (the pelvis' own frame at the start, x right, y up, z back): the let-go rifle is simulated again on
    # its own from where and how fast it left the hands, flung by this, the body keeping its recorded fall
    # (authoring.rifle_drop); None: the rifle as the ragdoll's fall left it
    drop_toss: tuple[float, float, float] | None = None
    # the let-go rifle left leaning on him falls again among the settled body once his arms go, from the
    # frame it last moved (authoring.rifle_settle): the settle laid prstow/prfire's arms down from under it
    # and left it standing on its magazine or muzzle, butt 19-36 cm up
    rifle_resettle: bool = False
    # s: a propped death's chest comes down from this time of the physics on, over its tail (its own motion
    # fading out, authoring.dead_settle._overlapped), not after it (None): the physics left prstow2dead and
    # prfire2dead propped on their elbows, head 30 cm up, until 3.1 and 1.4 s (the check's propped_s)
    lowered_at: float | None = None
    # the slaves' trunk settles onto the ground (slave_ground.rest_limbs) only once the master's arms and
    # head lie still too: lowered as his chest came down (lowered_at), prstow2dead's DI and M16 slaves swept
    # their right forearm 4.0 / 7.0 cm along the ground as it swung out
    slave_settle_arms_still: bool = False
    # cm: the slaves' trunk rest (slave_rest) brings their heels down to this however high they lay (None:
    # never higher than the check's 15 or where they lay): prstow2dead's DI, its toes laid on the ground
    # where the master's are, lay with its left heel 15.85 cm up
    slave_heels_cm: float | None = None
    # frames: the slaves' held rifle slides out of their body (slave_contacts._settle_rifle) until this many
    # frames past the release, fading out there, as the dropped rifle's clearing fades in (slave_ground
    # .clear_rifle): faded out before the release, prfire2dead's DI right upper arm lay 1.04 cm in the stock
    # at the release frame (13)
    slave_rifle_slid_past: int = 0
    # the slaves' trunk settles onto the ground (slave_ground.rest_limbs) once the master's pelvis and chest
    # lie down, however his root still turns, not once it is still: kfire2dead's DI, lifted by its arm in the
    # ground under it, hovered pelvis 6-11 cm up until his root stopped 0.6 s later (trunk_rise 5.28 -> 1.2)
    slave_settle_down: bool = False
    # s: a body on its back (arms_fall) lets its arms go this long before it is down, and they fall
    # 1.5 times as long (dead_settle.ArmsFall): kfire2dead's relaid top arm swept across in 0.6 s, hand 9 m/s
    arms_fall_early_s: float = 0.0
    # the slaves' arms are brought down where they rise once the master is down (authoring.slave_arms_down):
    # kfire2dead's early-falling top arm, over the DI's own chest, lifted its hand 14.3 cm after it lay
    slave_arms_down: bool = False
    # s: on his back (arms_fall), an arm falls this long from when he is down (dead_settle.ArmsFall.seconds;
    # None: 0.4): kstow2dead's left hand, 45 cm up, swept 80 cm round to his side in 0.4 s at 7.92 m/s
    arms_fall_s: float | None = None
    # s: on his back (arms_fall), the clip ends this long after the arms land (dead_settle.ArmsFall
    # .still_s; None: 0.1): kstow2dead's DI/M16 right hand, its arm falling 0.8 s, landed as the slaves'
    # trunk rest eased in over the last 0.5 s (slave_rest.EASE_FRAMES) and slid 3.27 cm
    arms_still_s: float | None = None
    # frames from the release (-1: the last held): the let-go rifle falls again from there among the finished
    # body, its arms left out (authoring.rifle_settle), flung by rifle_refall_toss; None: as recorded.
    # ststow2dead's, flung clear of his fall, landed 1.47 m from his hands; kfire2dead's stood on its butt
    rifle_refall: int | None = None
    rifle_refall_toss: tuple[float, float, float] = (0.0, 0.0, 0.0)  # N, the start pelvis' frame
    # the M16 slave's arms blend from their pose as the hands let go into the master's angles, not from the
    # goals tracked on (slaving._let_go_in_place): ststow2dead's, its rifle falling again, swung the right
    # shoulder 22.5 degrees in the frame after the release (max_frame_jump 20; before 19.5)
    slave_let_go_in_place: bool = False
    # a prone death's settle (lowered_at) lifts its arms no higher than just clear of where they lay and will
    # lie (dead_prone.LEVEL_WEIGHT): prfire2dead's right hand rose 12.2 -> 16.6 cm by his head as it lay down
    arms_lifted_level: bool = False
    # a prone death's arms, lifted while his chest comes down (authoring.dead_prone), are held low in the air:
    # crawl2dead's left hand rose 5.0 -> 9.4 cm in mid-air after his head was down (rest_rise 4.42 -> 1.06)
    arms_air_low: bool = False
    # the slaves' spine is bent so their belly and chest lie as high as the master's from the release on,
    # before the other rests (authoring.slave_spine), their arms lifted by the arm, their trunk not turned
    # by rest_limbs: prfire2dead's DI belly lay 2.8 cm in the ground, the body lifted out (trunk_rise 5.8)
    slave_spine_laid: bool = False
    # s: the slaves leave their start posture from rest over this, their frames up to the release retimed
    # (authoring.slave_start): prstow2dead's DI, laid by the spine, moved its head 0.59 m/s in frames 2-3
    slave_start_ease: float = 0.0
    # a standing death's feet stay where they leave the ground as his knees land, the knee, ankle and toes
    # opening under the falling thigh (authoring.feet_held): stfire2dead's shins swung up 45 degrees, feet
    # 17 cm off the ground, as his thighs came down flat
    feet_held: bool = False
    # s: the settle lays the legs from this time of the fall, as the knees land, a leg rising only until the
    # check's rest window opens (dead_settle.legs_landed_from); None: from the frame he is down. Laid then,
    # stfire2dead's legs lifted to turn out rose 6.9 cm at the knee after he was down (rest_rise_cm)
    legs_land_from: float | None = None
    # the body (master and slaves) is lowered where it hovers, never below the check's contact height
    # (authoring.grounded): tipped off his knee, kstow2dead's one foot on the ground lifted (leg_lift), he
    # hung 2.7 cm up for 0.15 s
    grounded: bool = False
    # s: as the hands let go, the arms' muscles aim where the arms are, turning to the program's shape over
    # this (deaths._Grip; 0: at once): the welds held the arms against springs aimed at the slump far off
    letgo_blend: float = 0.0
    # the let-go rifle's neighbours it is still inside of (a forearm) wait until it is clear of them instead
    # of pushing it out (Ragdoll.release's push_out): pushed out, the rifle flung the left forearm it lay in
    letgo_clear: bool = False
    # the fingers meet only the ground from the let-go on (Ragdoll.release's fingers), as the palms never meet
    # the rifle: the rifle pushed out of the forearm hit the left fingers wrapped round it
    letgo_fingers: bool = False
    # a propped death's settle lays his legs dragging no node on the ground as it lifts off (the check's
    # LIFT_OFF_CM, dead_legs.leg_slide): crawl2dead's left thigh, rolled out at 1.0-1.8 cm up, slid 2.3 cm
    legs_lift_off: bool = False
    # frames (held, caught up past the release): the slaves' arms keep their start pose, then catch up with
    # the solve while the hit lifts the body (authoring.slave_arms_late): prfire2dead's DI right forearm
    # dragged 5.4 cm along the ground as the snap faded its arm back (frames 0-9)
    slave_arms_late: tuple[int, int] = (0, 0)
    # grounded only before the pelvis is down (grounded.pelvis_down): lowered as they rolled onto their back
    # after, kstow2dead's DI slaves' pelvis rose 5.7 cm (trunk_rise_cm 1.64 -> 5.67)
    grounded_until_down: bool = False
    # the slaves alone are lowered where they hover (authoring.grounded; ``grounded`` lowers the master too):
    # crawl2dead's DI, its belly solved into the ground and the body lifted out, floated 2-3 cm, 0.10 s
    slave_grounded: bool = False
    # the slaves' arms go where the master's go after the release, lying or lifted (slave_ground._plants):
    # unheld once his arm lifted, each solve pass put crawl2dead's DI arm out sideways again, 8-10 cm
    slave_arms_follow: bool = False
    # the slaves' forearms lie still on the ground where the master's do, last (authoring.slave_lying):
    # prstow2dead's DI left forearm hovered 1.5-2.3 cm up and drifted 7 cm where his lay still
    slave_forearms_lying: bool = False
    # (joint name prefix, degrees): the legs' lift (legs_lift) turns those joints at most this much a frame
    # beyond the fall's own turn (leg_lift.lifted; others: leg_lift.STEP_DEG, 10): kfire2dead's rear foot,
    # lifted, popped 4.33 m/s
    legs_lift_step_deg: tuple[tuple[str, float], ...] = ()
    # frames: after the physics the arms leave the grip at their held pace, turning into the recorded fall
    # over this many (authoring.letgo_ease; 0: as recorded): ststow2dead's right hand jumped 15 cm (5.04 m/s)
    letgo_eased: int = 0
    # the legs' change is smoothed (legs_eased) at every leg DOF where any flicks (leg_lift.eased_legs'
    # together): ststow2dead's left knee, held by knee_hold, stuttered 6.4/0.6/5.0 degrees (pop 1.69 m/s)
    legs_eased_together: bool = False
    # share: the slaves' root moves back by this share of their belly node's slide on the ground as the trunk
    # turns (authoring.slave_belly_held): prfire2dead's DI belly, 0.6-1 cm up, swung 3.8 cm as he rocked
    slave_belly_held: float = 0.0
    # frames: (with slave_grounded) only each hover's first frames come down, its last this many
    # left in the air, no part off the ground lowered into contact (authoring.grounded.drop's leave):
    # stfire2dead's DI slaves, lowered whole, put their reaching hands down early (left hand slid 4.29 cm)
    slave_grounded_leave: int = 0


def _prone(
    name: str, start: str, force: float = 80.0, knee_damping: float = 1.0, pinned: bool = True
) -> DeathSpec:
    """A death of a soldier lying on his front: hit down on the upper torso, only the head slumping, quick;
    left propped on his elbows, his chest comes down after the physics (and, ``pinned``, his forearms stay
    where they lie)."""
    return DeathSpec(
        name,
        start,
        force,
        (0.0, -1.0, 0.0),
        "head",
        slump_time=0.25,
        fade=0.6,
        release=0.15,
        knee_damping=knee_damping,
        propped=True,
        pinned=pinned,
        slack_feet=True,
    )


def _prone_dead(name: str, start: str) -> DeathSpec:
    """A prone death (:func:`_prone`) whose fall leaves the prone posture from rest
    (:data:`PRONE_START_EASE`)."""
    return replace(_prone(name, start), start_ease=PRONE_START_EASE)


def _lying_prone(spec: DeathSpec) -> DeathSpec:
    """A death from a prone posture (PRONE_STOWED, PRONE_FIRE), as every one settles: the legs roll out one
    after the other, the chest is lowered from :data:`PRONE_LOWERED_AT`, the let-go rifle falls again among
    the body; its slaves settle once his arms lie still, their trunk laid by the spine (the DI's belly, shaped
    otherwise, lay 1-3 cm in the ground and the body was lifted out: rest_rise 4.0-4.5 cm) and their hands
    and forearms held where they rest (laid so, the M16's prstow forearm slid 4.30 cm, prfire's hand 3.26)."""
    return replace(
        spec,
        prone_legs_roll=True,
        rifle_resettle=True,
        lowered_at=PRONE_LOWERED_AT,
        slave_settle_arms_still=True,
        slave_spine_laid=True,
        slave_arms_pinned=True,
        slave_forearms_lying=True,
    )


# frames: crawl2dead's legs' lift smoothed (DeathSpec.legs_eased): his right thigh and left knee dragged 3.3
# and 3.1 cm as his legs rolled out (frames 36-72); lifted instead (DeathSpec.legs_lift) an ankle turned 8.3
# degrees in a frame and a foot popped 1.8 m/s; eased over 3 frames, 3.5 degrees and 0.76 m/s
CRAWL_LEGS_EASED = 3.0
# A crawler's arms stay propped (limp, his chest dropped onto them and the elbows splayed, the forearms slid
# 5-6 cm; held by contact_pin they still slid 4.4: the shoulders passed over the elbows) and his legs drawn
# until he is down (limp from the start, the knees splayed 3.5 cm); the settle lays the chest down. The
# rifle he cradled across his forearms is flung forward, ahead of his face (tossed to the side, it stayed
# under the face and the head rested on it, 11.8 cm up; 40-80 N did not move it off the forearms).
CRAWL_DEATH = replace(
    _prone("crawl2dead", "CRAWL", force=120.0, knee_damping=4.0, pinned=False),
    toss=200.0,
    toss_to=(0.0, 1.0, 0.3),
    kept=(*((j, MAX_SECONDS) for j in ("clavicle", "shoulder", "elbow")), ("hip", 0.45), ("knee", 0.45)),
    kept_tone=0.3,
    sunk=True,
    arms_air_low=True,
    slave_arm_out=True,
    slave_grounded=True,
    slave_arms_follow=True,
    slave_feet_slack=True,
    legs_lift_off=True,
    legs_lift=True,
    legs_eased=CRAWL_LEGS_EASED,
)
# s: the standing deaths' DeathSpec.legs_roll: rolled over KNEE_STRAIGHTEN (1 s) the legs turned on the
# ground after he lay still (ststow2dead's heels 15.4/17.4 cm from the physics), over this while he lands
# (10.1/11.4 cm; 18.3/20.0 to the active range over 1 s), the thighs sliding no further. Over 0.5 s the right
# hip was still rolling out as he landed on that thigh (frames 83-97): its nodes slid 3.30 cm over the
# ground; over 0.4 s the roll is done sooner, 2.78 (0.35: thigh 2.46 but the head 3.38 as he settles; 0.45:
# head 3.55 and an ankle flick of 8.5 degrees: the fall is chaotic in these, each was measured)
LEGS_ROLL = 0.4
# s: stfire2dead's (heels 15.4 -> 15.1 cm and its knee's rebound 3.9 -> 2.5 cm; over 0.6 s its left foot slid
# 6.3 cm as he landed, over 0.7 s the heel lay at 19.4: the fall is chaotic in these, each was measured)
STFIRE_LEGS_ROLL = 0.8
# s: stfire2dead's legs are laid from this time of his fall (DeathSpec.legs_land_from), his knees coming down
# (they land at 1.07-1.17 s, the trunk is down at 1.22): laid once he was down, the legs lifted to turn
# out rose 6.9 cm at the knee (rest_rise_cm); from 0.87-1.05 s their lift is done by then (rise 1.4-2.4 cm)
STFIRE_LEGS_LAND = 1.0
# s: prfire2dead leaves its posture from rest over this (DeathSpec.start_ease): its first frames 0.46 ->
# 0.14 m/s, its DI/M16 slaves' 0.57/0.67 -> 0.32/0.29 (over 0.25 s with its ankles rolled, branch
# proneheels14-wip: 0.08, slaves 0.27/0.23, but the DI slave's belly slid 8.1 cm). prstow2dead is not
# eased: eased, its master's right forearm lay still over the first frames while its DI slave's swept
# 5.8 cm along the ground (the slave's own start ease, authoring.slaving START_EASE_FRAMES; the master
# moving, that forearm was lifted off the ground by then)
PRONE_START_EASE = 0.1
# frames: prstow2dead's slaves hold their head at the start (DeathSpec.slave_head_held). The M16 slave's solve
# starts its neck 6.5 degrees off the PRONE_STOWED node's and swings it there over its first 10 frames; its
# first frame snapped and that change faded out over 12 frames, the head left at 0.59 m/s (0.62 faded over 24;
# held over 24: 0.49, the DI slave's 0.46 -> 0.45; it catches up at 1.6 m/s 0.2-0.3 s in, as it falls later)
PRSTOW_HEAD_HELD = 24
# share: prfire2dead's slaves' root takes back this much of their belly's slide (DeathSpec.slave_belly_held):
# the DI's belly node slid 3.83 cm (frames 25-96) as the root moved 2.5 cm over its pelvis and back; all of
# it: the pelvis slid 3.85 cm, a thigh 3.94, a foot 3.8; 0.45: belly 2.11, but the left foot skated
# 2.07 cm (M16 2.05; the check's foot_skate 2); 0.6: belly 1.53
PRFIRE_SLAVE_BELLY_HELD = 0.3
# s: prstow2dead's slaves, laid by the spine, leave PRONE_STOWED from rest over this (slave_start_ease): the
# hit presses his hips down 1.7 cm in his first 4 frames and the DI's belly, 1.1 cm into the ground, is lifted
# out with the body, its head rising 0.6 cm in frame 2-3 as his stays level: first frames 0.59 -> 0.13 m/s
# (M16 0.60 -> 0.15); 0.05: 0.31, its head then 0.64 m/s in frame 3-4 (0.60 at 4-5 here; his own 0.61)
PRSTOW_SLAVE_START_EASE = 0.08
# stfire2dead's rifle is flung to his right, a little down and back (pelvis frame): to his left, away from the
# fall (the default), he turned onto it and lay with his pelvis on it, 4.8 cm up; to his right it lies flat
# 32 cm clear of him and the trunk rests 1.7 cm up (right and down (1, -0.7, 0): his thighs skid 5.7 cm as
# he lands; back, or left and back, it ends under him again; at 100 N it rests tilted 38 cm up against him)
STFIRE_TOSS = (1.0, -0.5, 0.2)
# cm: kfire2dead's slaves' trunk rest may slide a resting part this far (DeathSpec.slave_rest_slide_cm): their
# pelvis 2.34 -> 1.54 cm up (the search's resting hands, knee, thigh and foot at their bounds); 2.0 once his
# top arm lay across his chest (DI pelvis 2.35 -> 1.27 cm, the check's rest limit 2; DI foot_skate 0.41); 2.5
# once his arms fell early (DeathSpec.arms_fall_early_s): the DI pelvis 2.43 -> 1.36 cm
KFIRE_REST_SLIDE = 2.5
# cm: kfire2dead's fallen arms reach no further than this past his shoulders toward his head
# (DeathSpec.arms_headward_cm): half on his side, his top (right) arm lay lowest curled over his head
KFIRE_ARMS_HEADWARD = 5.0
# s: kfire2dead's arms go this long before he is down (DeathSpec.arms_fall_early_s): his relaid top arm swept
# across his chest after he was down, hand 8.96 -> 3.08 m/s (0.4: 4.59, 0.6: 3.67; limb_rest_lag 0.2 s)
KFIRE_ARMS_EARLY = 0.8
# frames: kstow2dead's legs' flicking change by the pin and the lift smoothed (DeathSpec.legs_eased): the
# worst flick 18.7 degrees (right knee) -> 7.5 (the left wrist's, untouched), the ankles' 12.7 -> 1.9, its
# DI/M16 slaves' ankle 16.6 -> 2.6; turned least-worst last too (DeathSpec.turn_worst), its left thigh's slide
# as he lands 4.51 -> 2.02 cm and the chest's 4.48 -> 3.00 (plant_worst got the thigh 2.53 but its arms' fall
# then slid the chest 5.87)
KSTOW_LEGS_EASED = 1.5
# degrees a frame: kfire2dead's right leg's lift (DeathSpec.legs_lift_step_deg). At 10 the lift of his
# tucked rear foot turned the right knee 101.5 -> 111.3 degrees in one frame (0.47 s) and the foot popped
# 4.33 m/s, then the right hip 10 degrees at 1.33 s as he rolled onto his side (3.09 m/s); at 4: 0.93 (2.5:
# the foot, lifted later, slid 1.84 cm; eased instead, legs_eased 1.5: 2.53 m/s at 1.35 s). Both legs at 4,
# the left foot's lift came later and it skated 2.05 cm (the check's foot_skate 2)
KFIRE_LIFT_STEP = (("right_", 4.0),)
# s: kstow2dead's arms fall this long from when he is down (DeathSpec.arms_fall_s): his left hand, 45 cm up
# as he came down half on his side, swept round to his side while he rolled onto his back at 7.92 m/s in
# 0.4 s; 0.65 s: 5.02 (chest slide 3.05); 0.8 s: 4.09, limb_rest_lag 0.07 -> 0.2 s. Let go early instead
# (arms_fall_early_s 0.5-0.8) the arm, still on his side, was pressed into the ground (upper arm 1.1-2.6 cm)
KSTOW_ARMS_FALL = 0.8
# s: and the clip ends this long after they land (DeathSpec.arms_still_s): the slaves' trunk rest eases in
# over the last 0.5 s, after the arms lie
KSTOW_ARMS_STILL = 0.5
# N: ststow2dead's let-go rifle, fallen again on its own (DeathSpec.drop_toss). In his fall it was flung
# to his left (80 N, away from a fall straight ahead) and came to rest by his boots: the fall turns him onto
# his right side, his legs swinging round toward it (35 cm from the right foot, 1.8 m from his hands). Any
# other toss, or a later let-go, re-rolled the fall: let go unflung, his right thigh skidded 4.0 cm and his
# pelvis lay 10.4 cm up; flung forward, right or up (10-200 N) or let go at 0.3-0.45 s, the thigh skidded
# 3.6-5.8 cm, a foot rose 22-32 cm or the rifle lay under him (each was measured)
STSTOW_DROP = (20.0, 0.0, -90.0)
# ststow2dead's let-go rifle falls again among his finished body from the last frame the hands hold it
# (DeathSpec.rifle_refall), flung to his left and a little ahead (pelvis frame): it landed 1.47 m from his
# hands (STSTOW_DROP, 2.6 m/s), now 0.87. Unflung it lay under his right thigh, squeezed 4.3 cm into the
# ground; flung (-20..-80, 0, 0..-30) N it landed 0.69-1.37 m off, some through his legs (each was measured).
# Flung (-60, 0, -20) it lay on its top, sights down, 0.48 s before rolling onto its side (the check's
# rifle_top_down_s); a little more ahead, (-55..-65, 0, -28..-32), it lands on its side (each was measured)
STSTOW_REFALL = (-1, (-60.0, 0.0, -30.0))
# frames: ststow2dead's arms leave the grip over this many after the physics (DeathSpec.letgo_eased): the
# let-go's one-frame jump (left wrist 16.2 degrees, right hand 15 cm) spread out, the chaotic fall as it was
# (eased in the physics instead, letgo_fingers / knee_damping re-rolled it: he lay curled, pelvis 18 cm up)
STSTOW_LETGO_EASED = 8
# frames: ststow2dead's legs' change by the knee hold, the pins and the lift smoothed where it flicks, all the
# legs' DOFs together (DeathSpec.legs_eased, legs_eased_together): the knee hold stuttered his left knee
# 6.4/0.6/5.0 degrees a frame as he landed (pop 1.69 m/s, frame 90); eased DOF by DOF, the foot popped 3.91
STSTOW_LEGS_EASED = 1.0
# frames: stfire2dead's arms leave the grip over this many after the physics (DeathSpec.letgo_eased, as
# ststow2dead's): the let-go jumped his right hand in one frame (pop 4.88 m/s, DI 5.25, M16 forearm 2.27);
# over 6, 8 or 10 frames no arm pops (1.46 m/s), but the held right arm runs on into the falling rifle the
# longer it is eased: rifle_in_body 0.83 / 1.09 / 1.23 cm (limit 1; each was measured)
STFIRE_LETGO_EASED = 6
# frames: stfire2dead's DI/M16 slaves, pushing off their toes and reaching for the ground, hover 4 frames
# (62-65; the check allows 3): lowered at the hover's start only (DeathSpec.slave_grounded_leave), its last
# 3 left in the air. Lowered whole (slave_grounded alone), the reaching hands touched down two frames early
# and slid there (left hand 1.31 -> 4.29 cm)
STFIRE_SLAVE_HOVER_LEFT = 3
# frames after the release: kfire2dead's let-go rifle falls again among his body from here
# (DeathSpec.rifle_refall): recorded, it landed butt first by his left boot and stood there, leaning on
# nothing, 0.4 s (rifle_upright_s; 1 s seen from the front); from 6-8 frames it tips and lies flat by 1 s
# (from 2: it stood again on his legs at 1.3 s; from 30-40: it leaned on his boot until 1.2 s)
KFIRE_REFALL = 8
# N (the start pelvis' frame): kfire2dead's refallen rifle is flung ahead (DeathSpec.rifle_refall_toss):
# unflung it lay on its top, sights down, by his boot for 0.58 s before rolling onto its side (the check's
# rifle_top_down_s); flung 15-25 N ahead it lands on its side and lies there (each was measured)
KFIRE_REFALL_TOSS = (0.0, 0.0, -20.0)
# frames after the release: kstow2dead's let-go rifle falls again among his body from the last held frame
# (DeathSpec.rifle_refall), unflung: as recorded it flew 1.97 m, thrown clear as he pitched over; now it
# slides from his hands, lands by his front boot by 0.67 s and lies there, 0.23 m from where he let it go.
# From 0-5 frames it went 1.2-3.1 cm through a forearm left out of it (or flew 1.1 m), flung (+-20-40 N) too
KSTOW_REFALL = -1
# s: the prone deaths' chest comes down from this time of the physics on (DeathSpec.lowered_at), as the hit
# (0-0.55 s) ends: after the physics, they lay propped on their elbows, head 30 cm up, until 3.4 / 1.7 s
# (the check's propped_s); prfire2dead, from 0.35 s (0.4), lifted off a right forearm still sliding under
# him: it slid 5.1 (3.4) cm; from 0.45 s over a shorter settle (0.6, 0.7 s) his right hand swung up 3.9 (3.2)
# cm after his trunk was down (rest_rise)
PRONE_LOWERED_AT = 0.45
# cm: prstow2dead's slaves' heels at rest (DeathSpec.slave_heels_cm; the check's rest_foot limit 15)
PRSTOW_SLAVE_HEELS = 14.0
# frames: prfire2dead's slaves' held rifle slides out of the body until this far past the release
# (DeathSpec.slave_rifle_slid_past)
PRFIRE_RIFLE_SLID_PAST = 2
# frames: prfire2dead's slaves' arms keep PRONE_FIRE's pose this long and catch up this far past the release
# (DeathSpec.slave_arms_late), leaving it from rest over PRFIRE_SLAVE_START_EASE s (slave_start_ease; the
# held rifle, going with the chest, left at 0.55 m/s otherwise): the DI's right forearm 5.42 -> 2.67 cm,
# its left forearm's leap at the release 1.65 -> 1.19 m/s; the M16's right forearm 4.44 -> 3.89. Held 6
# and caught up by the release: a palm 1.01 cm off the rifle; by 4 past it: the left hand 1.55 m/s
PRFIRE_SLAVE_ARMS_LATE = (5, 6)
PRFIRE_SLAVE_START_EASE = 0.1
DEATHS: tuple[DeathSpec, ...] = (
    DeathSpec(
        "ststow2dead",
        "STAND_STOWED",
        120.0,
        (0.0, -0.3, -1.0),
        toss=80.0,
        drop_toss=STSTOW_DROP,
        rifle_refall=STSTOW_REFALL[0],
        rifle_refall_toss=STSTOW_REFALL[1],
        slave_let_go_in_place=True,
        pinned=True,
        knees_held=True,
        legs_roll=LEGS_ROLL,
        legs_settle=False,
        slave_arm_out=True,
        slave_trunk_rigid=True,
        slave_feet_landed=True,
        letgo_eased=STSTOW_LETGO_EASED,  # the let-go's right hand pop 5.04 m/s (DI 6.11) gone, the fall kept
        legs_lift=True,  # the right knee that dragged 5.88 cm as he pitched off it lifts: 2.07
        legs_eased=STSTOW_LEGS_EASED,
        legs_eased_together=True,
        slave_grounded=True,  # the DI/M16 slaves hung 2 cm up, frames 60-66 (unsupported_s 0.12 -> 0)
    ),
    DeathSpec(
        "stfire2dead",
        "STAND_FIRE",
        120.0,
        (0.0, -0.3, -1.0),
        knee_damping=4.0,
        toss=120.0,
        knee_straighten=0.5,
        hip_damping=13.0,
        arm_tone=0.08,
        pinned=True,
        legs_roll=STFIRE_LEGS_ROLL,
        toss_to=STFIRE_TOSS,
        slave_arms_pinned=True,
        feet_held=True,
        legs_land_from=STFIRE_LEGS_LAND,
        # its legs laid sooner, the DI/M16 slaves' left foot slid 3.68 cm after it landed; held where it lands
        # (slave_feet_landed), their right knee rose 3.01 cm as the trunk rested; its trunk laid by the root
        # alone too (as ststow2dead's), 0.35 cm
        slave_trunk_rigid=True,
        slave_feet_landed=True,
        letgo_eased=STFIRE_LETGO_EASED,  # the let-go's right hand pop 4.88 -> 1.46 m/s, the fall kept
        slave_grounded=True,  # the DI/M16 slaves' 4-frame hover (unsupported_s 0.067 -> 0.05)
        slave_grounded_leave=STFIRE_SLAVE_HOVER_LEFT,
    ),
    DeathSpec(
        "kstow2dead",
        "KNEEL_STOWED",
        100.0,
        (1.0, -0.3, 0.0),
        "upper",
        release=0.15,
        sideways=True,
        arm_tone=0.05,
        pinned=True,
        arms_fall=True,
        legs_lift=True,
        legs_eased=KSTOW_LEGS_EASED,
        turn_worst=True,
        turn_as_checked=True,  # chest 3.00 -> 2.95 cm (limit 3), the turn seeing the check's 16 directions
        slave_feet_knelt=True,
        arms_fall_s=KSTOW_ARMS_FALL,
        arms_still_s=KSTOW_ARMS_STILL,
        rifle_refall=KSTOW_REFALL,
        grounded=True,  # unsupported_s 0.15 (DI/M16 0.28) -> 0
        grounded_until_down=True,
    ),
    DeathSpec(
        "kfire2dead",
        "KNEEL_FIRE",
        100.0,
        (1.0, -0.3, 0.0),
        "upper",
        release=0.15,
        sideways=True,
        knee_damping=4.0,
        arms_fall=True,
        legs_lift=True,
        plant_worst=True,
        turn_worst=True,
        slave_feet_held=True,
        slave_rest_slide_cm=KFIRE_REST_SLIDE,
        arms_headward_cm=KFIRE_ARMS_HEADWARD,
        turn_as_checked=True,
        slave_settle_down=True,
        arms_fall_early_s=KFIRE_ARMS_EARLY,
        slave_arms_down=True,
        rifle_refall=KFIRE_REFALL,
        rifle_refall_toss=KFIRE_REFALL_TOSS,
        slave_let_go_in_place=True,
        grounded=True,  # unsupported_s 0.18 (DI/M16 0.35) -> 0
        legs_lift_step_deg=KFIRE_LIFT_STEP,  # the right (rear) foot's pop 4.33 -> 0.93 m/s
    ),
    replace(
        _lying_prone(_prone("prstow2dead", "PRONE_STOWED")),
        slave_head_held=PRSTOW_HEAD_HELD,
        slave_heels_cm=PRSTOW_SLAVE_HEELS,
        slave_start_ease=PRSTOW_SLAVE_START_EASE,
    ),
    # not eased: see PRONE_START_EASE
    replace(
        _lying_prone(_prone_dead("prfire2dead", "PRONE_FIRE")),
        slave_arms_held=True,
        slave_rifle_slid_past=PRFIRE_RIFLE_SLID_PAST,
        arms_lifted_level=True,
        slave_start_ease=PRFIRE_SLAVE_START_EASE,
        slave_arms_late=PRFIRE_SLAVE_ARMS_LATE,
        slave_belly_held=PRFIRE_SLAVE_BELLY_HELD,
    ),
    CRAWL_DEATH,
)


def death_specs() -> dict[str, DeathSpec]:
    return {d.name: d for d in DEATHS}


def spec_of(channelset_name: str) -> DeathSpec | None:
    """The death a channelset records (``kfire2dead.chset`` -> kfire2dead's spec), None if none."""
    return death_specs().get(channelset_name.split(".", 1)[0])


def dead_node(name: str) -> str:
    """The DEAD variant a death ends in: ``ststow2dead`` -> ``DEAD@ststow``."""
    return f"{DEAD}@{name.removesuffix('2dead')}"
