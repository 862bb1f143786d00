//! Ground truth and judging, from the simulator's own state and never published to the
//! daemon: the poses and projections a test checks against ([`truth`]), the success rule
//! ([`judge`]), the operator hint an operator would give the daemon ([`hint`]: the *generator*;
//! the hint's format is the wire contract's `handeye_wire::hint`), what the daemon claims,
//! judged from ground truth ([`watch`]; no move on a lost track: [`blind_moves`]), whether the target has a grasp the rules allow
//! ([`graspable`]: the thesis's rules on the block's true geometry), and a scripted pick that reads ground truth to check
//! that the arm can pick a block at all ([`script`]), and the run's verdict as `sim.json`
//! reports it ([`report`]).
//!
//! Depends on the simulator (which it reads) and on the renderer's camera model and face ids;
//! the simulator depends only on [`judge`] (it judges success every step). Inside: `watch` →
//! `hint` → `truth`, `watch` → `blind_moves`; `judge` and `script` stand alone.

pub mod blind_moves;
pub mod graspable;
pub mod hint;
pub mod judge;
pub mod report;
pub mod script;
pub mod truth;
pub mod watch;
