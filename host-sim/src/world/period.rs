//! One vehicle's period, once its messages and sensor returns are in: it decides
//! (messages → its view → its planner → command), moves by the exact unicycle (1) or
//! along its path, checks its goal at the period's end and takes its place after the
//! move. The world's loop ([`super::step`]) and a fleet's vehicle task
//! ([`crate::fleet`]) both run this, so the two differ only in how messages travel.

use super::handover::{step_place, Moved};
use super::vehicle::{Counters, StepCtx, Vehicle};
use super::TraceRow;
use crate::bus::Received;

impl<const N: usize> Vehicle<N> {
    /// The period `ctx.steps_done` of this vehicle: its trace row (the state at the
    /// period's start and the command applied) and what its move did to its place.
    pub fn period(
        &mut self,
        ctx: &StepCtx<'_>,
        inbox: &[Received],
        counters: &mut Counters,
    ) -> (TraceRow, Moved) {
        let ((v, w), row) = self.decide(ctx, inbox, counters);
        self.advance(v, w, ctx.lim.h);
        let end = (ctx.steps_done + 1) as f64 * ctx.lim.h;
        self.check_goal(end);
        (row, step_place(self, ctx.net, end))
    }
}
