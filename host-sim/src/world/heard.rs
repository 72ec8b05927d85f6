//! What one vehicle has heard of the others: the latest message from each, in whichever
//! frame it was sent (a state on a segment, or a crossing report at a junction), and the
//! others as its planner of the moment needs them (messages → world view → planner).
//!
//! Same rules as planner-core's `WorldView`, so that a straight road plans exactly as
//! before: records in the order first heard; a message not newer than the record, not
//! finite, with a negative speed or from itself is rejected and changes nothing. A vehicle
//! is one record whatever its frame: when it moves from a segment into a junction (or
//! out), its newer message replaces the old one, so no stale copy of it stays behind in
//! the other frame.
//!
//! Bounded memory: at most [`VIEW_CAP`] vehicles, and what it holds depends on what is
//! near, never on how many vehicles the world holds. Two vehicles matter to each other
//! only within the sum of their [`reach`]es (what each can cover in one plan at the speed
//! it goes, and its stopping distance) and [`SPARE_M`]: their *slack* ([`slack`]) is how
//! far apart they are beyond that. When full, a message from a new vehicle takes the place
//! of the record of most slack if its own is less (every vehicle repeats its message every
//! period, so a vehicle dropped while it could not matter is back as soon as it can). One
//! of positive slack that finds no place is simply not taken ([`Reject::Far`]). Only when
//! the view cannot hold every vehicle that may matter — a message of slack ≤ 0 finds no
//! place, or displaces one of slack ≤ 0 — is that an overflow: the receiver, which may now
//! miss a vehicle that matters, drives on its certified fallback.
//!
//! Why speeds, not a fixed radius: a fixed radius (the reach of two vehicles at vmax, 195
//! m) is what a jam fills. Standing 6 m apart on two lanes each way, a city grid puts
//! more than 256 vehicles within 195 m of each, and a world of 1,000 vehicles had 13,988
//! blind steps. Standing vehicles reach under 5 m (a second from rest at amax and the
//! safe distance at 3.8 m/s), so in a jam a view needs the twenty or so around it; at
//! speed, vehicles are spaced by their safe distances and as few fit within their longer
//! reach. Slack is judged on what a message says (position and speed at its stamp): a
//! record is renewed every period, and the planners take its age into account themselves.
//! (Before views were
//! bounded by relevance at all, any message that found no place was an overflow, so a
//! world of more than 257 vehicles froze: every vehicle heard more than its view held.)

use super::at::At;
use super::network::Network;
use super::plausible::{Bounds, Implausible};
use super::sensor::{seen_at, Seen, Sensed};
use crate::bus::Message;
use planner_core::crossing::{CrossingReport, PathVehicle};
use planner_core::{BodyLength, Instant, Other, Sensing, VehicleState};

/// Beyond the claim's own reach and the sensors' error, the margin (m) by which a claim
/// must be inside the sensors' cover, or away from its return, to be belied
/// ([`View::belied`]): the plausibility checks' position slack, and as much again for a
/// lane the claim may leave sideways.
pub const BELIED_SLACK_M: f64 = 1.0;

/// Vehicles one view holds: more than fit near one vehicle at any density (within
/// 100 m of road in every direction a few lanes hold fewer than 200).
pub const VIEW_CAP: usize = 256;

/// The latest message from one vehicle.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Record {
    /// A state in segment `segment`'s frame.
    Lane {
        /// The state.
        state: VehicleState<f64>,
        /// Its segment.
        segment: usize,
    },
    /// A crossing report at junction `junction`, stamped `stamp`.
    Crossing {
        /// The report.
        report: CrossingReport<f64>,
        /// Its junction.
        junction: usize,
        /// Sender's time stamp.
        stamp: Instant,
    },
}

impl Record {
    /// `self` (newer) against `last`, the record held of the same sender: checked when
    /// both are in the same frame (a state on the same segment, a report at the same
    /// junction); a move between frames is checked only for its speed.
    fn plausible(&self, last: Option<&Record>, b: &Bounds) -> Result<(), Implausible> {
        match (*self, last) {
            (
                Record::Lane { state, segment },
                Some(&Record::Lane {
                    state: l,
                    segment: ls,
                }),
            ) if ls == segment => b.state(Some(&l), &state),
            (Record::Lane { state, .. }, _) => b.state(None, &state),
            (
                Record::Crossing {
                    report,
                    junction,
                    stamp,
                },
                Some(&Record::Crossing {
                    report: l,
                    junction: lj,
                    stamp: at,
                }),
            ) if lj == junction => b.report(Some((&l, at)), &report, stamp),
            (Record::Crossing { report, stamp, .. }, _) => b.report(None, &report, stamp),
        }
    }

    /// Marks the record's vehicle as one that does not cooperate (a state; a crossing
    /// report carries no such flag). Its braking limit stays: it came in a message that
    /// was trusted, from a vehicle that cooperated then, so the stopping point that
    /// message bounds stays valid — and a follower that came close on that bound must
    /// not lose it now (docs/spec.md §11, "A credit is never withdrawn").
    fn distrusted(mut self) -> Self {
        if let Record::Lane { state, .. } = &mut self {
            state.cooperative = false;
        }
        self
    }

    /// What it claims, as sensors would see its vehicle (`longest`: its length if it
    /// declared none).
    fn seen(&self, longest: f64) -> Seen {
        match *self {
            Record::Lane { state, segment } => Seen {
                id: state.id,
                at: At::Lane {
                    seg: segment,
                    x: state.x,
                    y: state.y,
                    theta: state.theta,
                    lane: state.lane,
                    alpha: state.alpha,
                    beta: state.beta,
                },
                v: state.v,
                length: state.length.map_or(longest, BodyLength::m),
            },
            Record::Crossing {
                report, junction, ..
            } => Seen {
                id: report.id,
                at: At::Crossing {
                    junction,
                    route: report.route,
                    s: report.s,
                },
                v: report.v,
                length: report.length,
            },
        }
    }

    /// Its vehicle's speed (m/s).
    fn speed(&self) -> f64 {
        match *self {
            Record::Lane { state, .. } => state.v,
            Record::Crossing { report, .. } => report.v,
        }
    }

    fn id_stamp(&self) -> (u16, Instant) {
        match *self {
            Record::Lane { state, .. } => (state.id, state.stamp),
            Record::Crossing { report, stamp, .. } => (report.id, stamp),
        }
    }
}

/// Why a message was not taken (the view is unchanged).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Reject {
    /// The receiver's own.
    Own,
    /// Not finite, or a negative speed.
    Invalid,
    /// Not newer than what is held.
    Stale,
    /// The view is full of vehicles that matter more than this one ([`slack`]), and this
    /// one may matter (slack ≤ 0): an overflow.
    Full,
    /// The view is full of vehicles that matter more than this one, which cannot matter
    /// now (slack > 0).
    Far,
    /// Physically impossible after the last message accepted from the sender
    /// ([`super::plausible`]): the sender is a suspect from now on.
    Implausible(Implausible),
    /// From a suspect: nothing it says is taken any more ([`View::take`]).
    Distrusted,
}

/// Distance (m) to spare beyond the sum of two vehicles' reaches ([`slack`]).
pub const SPARE_M: f64 = 20.0;

/// A receiver as its view judges what matters to it: where it is in the world (m) and its
/// speed (m/s).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Here {
    /// Its centre in the world.
    pub at: (f64, f64),
    /// Its speed.
    pub v: f64,
}

/// How far (m) from itself a vehicle going at `v` can matter to a plan: a second of travel
/// and its safe distance dS (8), both at the speed it may reach within that second
/// (v + amax·1 s, at most vmax; Table I). A multi-lane plan looks no further, ahead or
/// behind (a follower in the target lane must keep dS toward it); a crossing planner
/// takes only the vehicles on its own path. At vmax it is 77.0 m; standing, 4.75 m. In a
/// `fleet` with trucks dS is at the weakest braking limit and half the longest vehicle's
/// extra length is added (centres are measured, and a truck's front is 6 m further from
/// its centre than a car's): a truck at vmax, 109.6 m.
pub fn reach(v: f64, fleet: super::Fleet) -> f64 {
    let lim = crate::monitor::Limits::table_i();
    let v = (v.max(0.0) + lim.a_max).min(lim.v_max);
    lim.safe_distance_at(v, fleet.weakest_brake) + v + 0.5 * (fleet.longest_m - super::LENGTH_M)
}

/// How far apart (m) two vehicles `d` apart at speeds `v` and `w` are beyond what can
/// matter between them in `fleet`: `d` less both reaches and [`SPARE_M`]. At most 0:
/// either may matter to the other's plan.
pub fn slack(d: f64, (v, w): (f64, f64), fleet: super::Fleet) -> f64 {
    d - reach(v, fleet) - reach(w, fleet) - SPARE_M
}

/// The distance (m) beyond which no vehicle can matter to a vehicle's plan this period on
/// `net`, whose roads allow at most `v_max`: the reach of a multi-lane plan — twice the
/// safe distance dS(vmax) (8) plus a second at vmax, for vehicles ahead and behind alike —
/// and the diagonal of the largest junction's communication region (a manager hears every
/// vehicle in A_C), whichever is larger, with [`SPARE_M`]. With Table I and the four-leg
/// layout of docs/spec.md: max(155, 175) + 20 = 195 m. With trucks in the `fleet`, dS
/// is at the weakest braking limit and the longest vehicle's extra length is added (a
/// 16.5 m truck braking at 4.5 m/s²: 256 m). A record of a vehicle within it that falls
/// silent is kept ([`View::forget_silent`]); which records a full view keeps is judged
/// by [`slack`].
pub fn relevance_radius(net: &Network, v_max: f64, fleet: super::Fleet) -> f64 {
    let lim = crate::monitor::Limits::table_i();
    let lanes = 2.0 * (lim.safe_distance_at(v_max, fleet.weakest_brake) + v_max) + fleet.longest_m
        - super::LENGTH_M;
    let junctions = net
        .junctions
        .iter()
        .map(|j| {
            2.0 * std::f64::consts::SQRT_2 * (j.layout.spec.half_size + j.layout.spec.comm_margin)
        })
        .fold(0.0, f64::max);
    lanes.max(junctions) + SPARE_M
}

/// Where a record's vehicle is in the world (m), for keeping the nearest.
fn where_is(r: &Record, net: &Network) -> (f64, f64) {
    match *r {
        Record::Lane { state, segment } => {
            net.segments.get(segment).map_or((state.x, state.y), |s| {
                let p = s.to_world(state.x, state.y, 0.0);
                (p.x, p.y)
            })
        }
        Record::Crossing {
            report, junction, ..
        } => net.junctions.get(junction).map_or((0.0, 0.0), |j| {
            let p = j.pose(report.route, report.s);
            (p.x, p.y)
        }),
    }
}

/// The latest record of up to [`VIEW_CAP`] other vehicles.
#[derive(Debug, Clone)]
pub struct View {
    own: u16,
    records: Vec<Record>,
    bounds: Bounds,
    /// Senders that have sent an implausible message (at most [`VIEW_CAP`]; the oldest
    /// suspicion is forgotten first).
    suspects: Vec<u16>,
    /// Per record, how far (m) its vehicle was from this one when it was last taken.
    heard_from: Vec<f64>,
    /// Per record, its [`slack`] toward this one when it was last taken (every vehicle
    /// sends each period, so it is at most a period old for a vehicle that is heard).
    slacks: Vec<f64>,
    /// Per record, its vehicle's id: what every message is looked up by, kept apart so
    /// the lookup reads two bytes a record (a view of a dense world holds hundreds).
    ids: Vec<u16>,
    /// Beyond this distance (m) no vehicle at any speed can matter to a plan: a silent
    /// vehicle heard within it is kept ([`View::forget_silent`]).
    relevant_m: f64,
    /// A record that may matter was displaced or refused since the last
    /// [`View::take_overflow`].
    overflowed: bool,
    /// The world's fleet: how far a record can matter ([`slack`]).
    fleet: super::Fleet,
}

impl View {
    /// An empty view for vehicle `own`, to which no vehicle farther than `relevant_m` (m)
    /// can matter at any speed ([`relevance_radius`]).
    pub fn new(own: u16, relevant_m: f64) -> Self {
        Self {
            own,
            records: Vec::new(),
            heard_from: Vec::new(),
            slacks: Vec::new(),
            ids: Vec::new(),
            bounds: Bounds::table_i(),
            suspects: Vec::new(),
            relevant_m,
            overflowed: false,
            fleet: super::Fleet::default(),
        }
    }

    /// The view of a vehicle in a world of `fleet`: with trucks, a record matters from
    /// farther ([`reach`]).
    pub fn for_fleet(mut self, fleet: super::Fleet) -> Self {
        self.fleet = fleet;
        self
    }

    /// Forgets the records of vehicles that fell silent beyond the relevance radius: a
    /// record not renewed for longer than the notification bound `notify` (plus a period
    /// `h`), of a vehicle farther than the radius when last heard. A radio of limited range
    /// ([`crate::bus::InProcessBus::set_range`]) stops delivering a vehicle that drives
    /// away; without this its record would stay where it was last heard, a phantom in the
    /// road. A vehicle within reach is heard within the notification bound — the bus's
    /// promise — so one silent for longer was out of range, and one that comes back within
    /// range is heard again before it can matter.
    pub fn forget_silent(&mut self, now: Instant, (notify, h): (f64, f64)) {
        let relevant = self.relevant_m;
        // A suspect's record is silent because its words are refused, not because it is
        // far: it stays.
        let suspects = std::mem::take(&mut self.suspects);
        self.retain_where(|r, from| {
            let age = now.since(r.id_stamp().1).as_secs::<f64>();
            age <= notify + h || from <= relevant || suspects.contains(&r.id_stamp().0)
        });
        self.suspects = suspects;
    }

    /// Keeps the records (and their distances) for which `keep` holds.
    fn retain_where(&mut self, keep: impl Fn(&Record, f64) -> bool) {
        let mut i = 0;
        while i < self.records.len() {
            match (self.records.get(i), self.heard_from.get(i)) {
                (Some(r), Some(&d)) if !keep(r, d) => {
                    self.records.remove(i);
                    self.heard_from.remove(i);
                    self.slacks.remove(i);
                    self.ids.remove(i);
                }
                _ => i += 1,
            }
        }
    }

    /// `true` if, since the last call, a record that may matter (slack ≤ 0) was displaced
    /// or refused: the view could not hold every vehicle that may matter.
    pub fn take_overflow(&mut self) -> bool {
        std::mem::take(&mut self.overflowed)
    }

    /// Takes a message heard by the receiver as it is (`me`) on `net`: states and crossing reports
    /// replace the sender's record when newer; `Left` drops a crossing record at that
    /// junction (not a state the vehicle has sent since, from its next segment); `Gone`
    /// drops every record of a vehicle that left the network. Grants are not for the view
    /// (`Ok`).
    ///
    /// A sender that has sent one implausible state or report is a suspect: nothing more
    /// it says is taken — not its states (a lie of a few metres becomes "plausible" again
    /// a few periods after the jump), not its `Left` or `Gone` (which would make the
    /// others forget it). Its last trusted record stays, ageing, and marked as a vehicle
    /// that does not cooperate, so the planners take it at the worst case reachable from
    /// there: a vehicle ahead no further on than its ghost from that position (v ≥ 0 and
    /// its declared limit; the credit a leader-aware follower gave it stays), one behind
    /// inflated at amax for the age, and no lane change starting in front of it (stale
    /// data). Safety never rests on its word again. A vehicle with onboard range sensors
    /// drops the record before it plans ([`View::belied`]).
    pub fn take(&mut self, msg: &Message, net: &Network, me: Here) -> Result<(), Reject> {
        if !matches!(msg, Message::Grant { .. }) && self.suspects.contains(&msg.sender()) {
            return Err(Reject::Distrusted);
        }
        let rec = match *msg {
            Message::State { state, segment } => {
                let f = [state.x, state.y, state.theta, state.v, state.omega];
                if !f.iter().all(|x| x.is_finite()) || state.v < 0.0 {
                    return Err(Reject::Invalid);
                }
                // Only a cooperating vehicle's limit bounds where it can stop.
                let brake = state.brake.filter(|_| state.cooperative);
                let state = VehicleState { brake, ..state };
                Record::Lane { state, segment }
            }
            Message::Crossing {
                report,
                stamp,
                junction,
            } => {
                if !(report.s.is_finite() && report.v >= 0.0) {
                    return Err(Reject::Invalid);
                }
                Record::Crossing {
                    report,
                    junction,
                    stamp,
                }
            }
            Message::Left { id, at, junction } => {
                self.retain_where(|r, _| {
                    !matches!(*r, Record::Crossing { report, junction: j, stamp }
                        if report.id == id && j == junction && stamp <= at)
                });
                return Ok(());
            }
            Message::Gone { id, at } => {
                self.retain_where(|r, _| {
                    let (rid, stamp) = r.id_stamp();
                    rid != id || stamp > at
                });
                return Ok(());
            }
            Message::Grant { .. } => return Ok(()),
        };
        let (id, stamp) = rec.id_stamp();
        if id == self.own {
            return Err(Reject::Own);
        }
        let full = self.records.len() >= VIEW_CAP;
        let held = self.ids.iter().position(|&r| r == id);
        let last = held.and_then(|i| self.records.get(i));
        if last.is_some_and(|r| stamp <= r.id_stamp().1) {
            return Err(Reject::Stale);
        }
        if let Err(why) = rec.plausible(last, &self.bounds) {
            self.suspect(id);
            return Err(Reject::Implausible(why));
        }
        let from = distance(where_is(&rec, net), me.at);
        let slack = slack(from, (me.v, rec.speed()), self.fleet);
        match held {
            Some(i) => {
                self.put(i, rec, from, slack);
                Ok(())
            }
            None if full => self.replace_least_relevant(rec, from, slack),
            None => {
                self.records.push(rec);
                self.heard_from.push(from);
                self.slacks.push(slack);
                self.ids.push(id);
                Ok(())
            }
        }
    }

    /// For a vehicle with onboard sensors `sn`, on it as `me`: checks every record against
    /// what they returned this period (`returns`, [`Sensed::ids`]) at `now`, makes a
    /// suspect of each vehicle whose claim they belie, and drops every suspect's record.
    ///
    /// A claim is belied where it puts its vehicle inside the sensors' cover by more than
    /// the vehicle can have moved since its stamp at `v_max`, and twice the sensors'
    /// error, and the sensors returned it nowhere, or farther from the claim than that.
    /// Why: a lie that stays within the physical bounds from the first report on cannot
    /// be told from the truth by the reports (`plausible`), and it held honest vehicles
    /// for good — a vehicle inside A_S stopped behind a liar's claim 5 m ahead of it
    /// while the liar stood 24 m behind it (`host-sim liars`, case 24). Safety never
    /// rested on the claim: a vehicle with sensors plans on their returns and takes the
    /// space beyond their cover as blocked, so a record made a suspect, and dropped,
    /// removes no constraint the returns do not impose themselves.
    ///
    /// Why drop a suspect's record rather than keep it, as a vehicle without sensors
    /// must ([`View::take`]): the record can only add a constraint the returns already
    /// impose or one they show false. Kept, it stood still for good: a follower stopped
    /// behind the ghost of a liar that had long crossed and left (`host-sim liars`, case
    /// 23 under PIPE, 10 s still before the deadlock report).
    pub fn belied(
        &mut self,
        net: &Network,
        (me, sn): (&Seen, &Sensing<f64>),
        returns: &Sensed,
        (now, v_max): (Instant, f64),
    ) {
        let err = sn.position_error_m;
        let belied: Vec<u16> = self
            .records
            .iter()
            .filter_map(|r| {
                let (id, stamp) = r.id_stamp();
                let margin = v_max * now.since(stamp).as_secs::<f64>() + 2.0 * err + BELIED_SLACK_M;
                let claimed = seen_at(net, me, &r.seen(self.fleet.longest_m), sn, margin)?;
                let returned = returns.ids.iter().find(|&&(i, _)| i == id);
                returned
                    .is_none_or(|&(_, at)| (at - claimed).abs() > margin)
                    .then_some(id)
            })
            .collect();
        for &id in &belied {
            self.suspect(id);
        }
        let suspects = std::mem::take(&mut self.suspects);
        self.retain_where(|r, _| !suspects.contains(&r.id_stamp().0));
        self.suspects = suspects;
    }

    /// Makes `id` a suspect: its record held now says it does not cooperate (it may
    /// accelerate at amax and ignores intentions, planner-core's conservative reading),
    /// and nothing it sends is taken from now on.
    fn suspect(&mut self, id: u16) {
        if !self.suspects.contains(&id) {
            if self.suspects.len() >= VIEW_CAP {
                self.suspects.remove(0);
            }
            self.suspects.push(id);
        }
        for r in self.records.iter_mut().filter(|r| r.id_stamp().0 == id) {
            *r = r.distrusted();
        }
    }

    /// Writes record `i`: `rec`, `from` m away, of slack `slack`, and its id.
    fn put(&mut self, i: usize, rec: Record, from: f64, slack: f64) {
        if let (Some(r), Some(f), Some(k), Some(id)) = (
            self.records.get_mut(i),
            self.heard_from.get_mut(i),
            self.slacks.get_mut(i),
            self.ids.get_mut(i),
        ) {
            (*id, *r, *f, *k) = (rec.id_stamp().0, rec, from, slack);
        }
    }

    /// A full view takes `rec` (`from` m away, of slack `slack`) in place of its record of
    /// most slack, if that is more (an overflow if it was ≤ 0); else `rec` is refused, as
    /// an overflow if its own slack is ≤ 0.
    fn replace_least_relevant(&mut self, rec: Record, from: f64, slack: f64) -> Result<(), Reject> {
        let least = self
            .slacks
            .iter()
            .copied()
            .enumerate()
            .max_by(|a, b| a.1.total_cmp(&b.1));
        match least {
            Some((i, most)) if slack < most => {
                self.put(i, rec, from, slack);
                self.overflowed |= most <= 0.0;
                Ok(())
            }
            _ if slack > 0.0 => Err(Reject::Far),
            _ => {
                self.overflowed = true;
                Err(Reject::Full)
            }
        }
    }

    /// Every record.
    pub fn records(&self) -> &[Record] {
        &self.records
    }

    /// The vehicles on segment `seg` as its multi-lane planner wants them, at `now`, each
    /// as long as it says (`length` if a state declares none), into `out` (cleared first): states sent on it, and crossing reports
    /// of vehicles whose path lies on it there (the inlet part before a stop line, the
    /// outlet part after a junction) — taken in its frame, its lane, and going straight.
    pub fn others_on(
        &self,
        net: &Network,
        seg: usize,
        now: Instant,
        length: f64,
        out: &mut heapless::Vec<Other<f64>, VIEW_CAP>,
    ) {
        out.clear();
        for r in &self.records {
            let other = match *r {
                Record::Lane { state: s, segment } if segment == seg => Other {
                    alpha: s.alpha,
                    beta: s.beta,
                    cooperative: s.cooperative,
                    brake: s.brake,
                    ..Other::v2v(
                        s.id,
                        s.x,
                        s.v,
                        s.length.map_or(length, BodyLength::m),
                        s.lane,
                        now.since(s.stamp).as_secs(),
                    )
                },
                Record::Crossing {
                    report,
                    junction,
                    stamp,
                } => match net.on_segment(junction, report.route, report.s) {
                    Some((sg, x, lane)) if sg == seg => {
                        let age = now.since(stamp).as_secs();
                        // A crossing vehicle is driven by its planner: its declared
                        // limit bounds its stop as on a lane.
                        Other {
                            brake: report.brake,
                            ..Other::v2v(report.id, x, report.v, report.length, lane, age)
                        }
                    }
                    _ => continue,
                },
                Record::Lane { .. } => continue,
            };
            // Cannot fail: `out` holds as many as the view.
            let _ = out.push(other);
        }
    }

    /// The crossing reports at junction `j`, with their stamps, in the order first heard.
    pub fn reports_at(
        &self,
        j: usize,
    ) -> impl Iterator<Item = (CrossingReport<f64>, Instant)> + '_ {
        self.records.iter().filter_map(move |r| match *r {
            Record::Crossing {
                report,
                junction,
                stamp,
            } if junction == j => Some((report, stamp)),
            _ => None,
        })
    }

    /// The vehicles along junction `j`'s route `route` heard of on the segments that
    /// carry its inlet or outlet, in its lane or changing into it (states), and of those
    /// crossing the next junction whose inlet is that outlet's segment (reports); reports
    /// at `j` itself are the crossing planner's own business.
    ///
    /// Those whose braking limit is known (a cooperating vehicle in the lane, a planner
    /// crossing the next junction) come as reports on `route` itself, stamped as heard,
    /// as long as they say (`length` if a state declares none), so a leader-aware crossing planner credits them like any leader on
    /// its path: a follower closed up on its leader by the credit keeps it when the
    /// leader leaves the junction. The rest are positions, walls: vehicles changing into
    /// the lane (an entering vehicle's check takes the follower at the paper's wall, so
    /// it is not credited), and those that declared no limit.
    pub fn on_path(&self, net: &Network, (j, route): (usize, u8), length: f64) -> OnPath {
        let mut out = OnPath::default();
        for r in &self.records {
            match *r {
                Record::Lane { state, segment } => {
                    // In its lane, and in the lane it is changing into: (17) let it start
                    // the change assuming the followers there keep the invariant toward
                    // it from then on, and a follower still on this junction's outlet
                    // drives this crossing planner, not a multi-lane one that would see
                    // the change itself (the grid at 500 veh/h: a follower
                    // leaving a junction closed in on a vehicle changing into its lane).
                    let lane = net.on_route(segment, state.x, state.lane, j, route);
                    let declared = state.length.map_or(length, BodyLength::m);
                    let report = |s| CrossingReport {
                        id: state.id,
                        route,
                        s,
                        v: state.v,
                        length: declared,
                        brake: state.brake,
                    };
                    let wall = |s| PathVehicle {
                        s,
                        length: declared,
                    };
                    match (lane, state.brake) {
                        (Some(s), Some(_)) => out.leaders.push((report(s), state.stamp)),
                        (Some(s), None) => out.walls.push(wall(s)),
                        (None, _) => {}
                    }
                    let entering = state
                        .alpha
                        .and_then(|a| net.on_route(segment, state.x, a, j, route));
                    out.walls.extend(entering.map(wall));
                }
                Record::Crossing {
                    report,
                    junction,
                    stamp,
                } if junction != j => {
                    let Some(s) = net
                        .on_segment(junction, report.route, report.s)
                        .and_then(|(seg, x, lane)| net.on_route(seg, x, lane, j, route))
                    else {
                        continue;
                    };
                    match report.brake {
                        Some(_) => out
                            .leaders
                            .push((CrossingReport { route, s, ..report }, stamp)),
                        None => out.walls.push(PathVehicle {
                            s,
                            length: report.length,
                        }),
                    }
                }
                Record::Crossing { .. } => {}
            }
        }
        out
    }
}

/// What a crossing planner hears of the vehicles on its path from other frames
/// ([`View::on_path`]).
#[derive(Debug, Default)]
pub struct OnPath {
    /// Vehicles taken as walls: where along the path, and as long as they declared (or
    /// the longest expected).
    pub walls: Vec<PathVehicle<f64>>,
    /// Vehicles whose braking limit is known, as reports on the path, with their stamps.
    pub leaders: Vec<(CrossingReport<f64>, Instant)>,
}

/// The distance (m) between two points: a square root of squares, not `hypot` (which
/// guards against overflow no world coordinate, at most 10⁶ m, can reach, at several
/// times the cost: a view of a dense world measures every message it takes).
fn distance(a: (f64, f64), b: (f64, f64)) -> f64 {
    let (dx, dy) = (a.0 - b.0, a.1 - b.1);
    (dx * dx + dy * dy).sqrt()
}
