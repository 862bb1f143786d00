//! The four contours of the hard loop: gripper and target, in the left and right views,
//! updated together on one stereo pair.

use super::contour_tracker::ContourTracker;
use super::state::TrackState;
use crate::image::ImageView;

/// What a tracker follows.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Role {
    Gripper,
    Target,
}

/// Which camera of the stereo pair.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum View {
    Left,
    Right,
}

impl Role {
    pub const ALL: [Role; 2] = [Role::Gripper, Role::Target];
}

impl View {
    pub const ALL: [View; 2] = [View::Left, View::Right];
}

#[inline]
fn slot(role: Role, view: View) -> usize {
    (role as usize) * 2 + view as usize
}

/// States of the four slots after an update; `None` for an inactive slot.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct StereoStates {
    states: [Option<TrackState>; 4],
}

impl StereoStates {
    pub fn get(&self, role: Role, view: View) -> Option<TrackState> {
        self.states[slot(role, view)]
    }

    /// Both views of `role` are active and tracking.
    pub fn pair_tracking(&self, role: Role) -> bool {
        View::ALL.iter().all(|v| matches!(self.get(role, *v), Some(TrackState::Tracking)))
    }

    /// Every active slot is tracking (true when none is active).
    pub fn all_active_tracking(&self) -> bool {
        self.states.iter().flatten().all(|s| s.is_tracking())
    }
}

/// Gripper + target, left + right: four [`ContourTracker`]s updated in one call. Each slot
/// can hold no tracker or an inactive one (kept built, so re-activating allocates nothing).
///
/// ```
/// use handeye_vision::image::ImageBuf;
/// use handeye_vision::tracker::{ContourTracker, Role, StereoTrackerSet, TrackerConfig, View};
/// let mut left = ImageBuf::filled(160, 120, 200);
/// for y in 40..80 { for x in 60..100 { left.set(x, y, 50); } }
/// let right = left.clone();
/// let square = [[59.5, 39.5], [99.5, 39.5], [99.5, 79.5], [59.5, 79.5]];
/// let mut set = StereoTrackerSet::new();
/// set.insert(Role::Target, View::Left, ContourTracker::new(TrackerConfig::default(), &square).unwrap());
/// set.insert(Role::Target, View::Right, ContourTracker::new(TrackerConfig::default(), &square).unwrap());
/// let states = set.update(&left.view(), &right.view(), 0.02);
/// assert!(states.pair_tracking(Role::Target));
/// assert_eq!(states.get(Role::Gripper, View::Left), None);
/// ```
#[derive(Debug, Clone, Default)]
pub struct StereoTrackerSet {
    trackers: [Option<ContourTracker>; 4],
    active: [bool; 4],
}

impl StereoTrackerSet {
    /// An empty set: all four slots inactive.
    pub fn new() -> Self {
        Self::default()
    }

    /// Puts `tracker` in the slot (active), returning what was there.
    pub fn insert(&mut self, role: Role, view: View, tracker: ContourTracker) -> Option<ContourTracker> {
        let s = slot(role, view);
        self.active[s] = true;
        self.trackers[s].replace(tracker)
    }

    /// Takes the tracker out of a slot.
    pub fn remove(&mut self, role: Role, view: View) -> Option<ContourTracker> {
        let s = slot(role, view);
        self.active[s] = false;
        self.trackers[s].take()
    }

    /// Marks a slot active or inactive; an inactive slot is skipped by `update`. Returns false
    /// when the slot holds no tracker (it then stays inactive).
    pub fn set_active(&mut self, role: Role, view: View, active: bool) -> bool {
        let s = slot(role, view);
        self.active[s] = active && self.trackers[s].is_some();
        self.trackers[s].is_some()
    }

    pub fn is_active(&self, role: Role, view: View) -> bool {
        self.active[slot(role, view)]
    }

    pub fn get(&self, role: Role, view: View) -> Option<&ContourTracker> {
        self.trackers[slot(role, view)].as_ref()
    }

    pub fn get_mut(&mut self, role: Role, view: View) -> Option<&mut ContourTracker> {
        self.trackers[slot(role, view)].as_mut()
    }

    /// Updates every active tracker on its view, `dt_s` seconds after the previous pair.
    pub fn update(&mut self, left: &ImageView<'_>, right: &ImageView<'_>, dt_s: f64) -> StereoStates {
        self.update_timed(left, right, dt_s, || 0).0
    }

    /// [`Self::update`], also measuring each slot's update with `now_ns` (read before and
    /// after each tracker; vision has no clock of its own, so the caller passes one). The
    /// durations are in slot order — gripper left, gripper right, target left, target right —
    /// and 0 only for a slot that was not updated (an update reads at least 1 ns).
    ///
    /// ```
    /// use std::cell::Cell;
    /// use handeye_vision::image::ImageBuf;
    /// use handeye_vision::tracker::{ContourTracker, Role, StereoTrackerSet, TrackerConfig, View};
    /// let mut img = ImageBuf::filled(160, 120, 200);
    /// for y in 40..80 { for x in 60..100 { img.set(x, y, 50); } }
    /// let square = [[59.5, 39.5], [99.5, 39.5], [99.5, 79.5], [59.5, 79.5]];
    /// let mut set = StereoTrackerSet::new();
    /// set.insert(Role::Target, View::Right, ContourTracker::new(TrackerConfig::default(), &square).unwrap());
    /// let clock = Cell::new(0u64);
    /// let tick = || { clock.set(clock.get() + 1_000); clock.get() }; // 1 µs per reading
    /// let (_, ns) = set.update_timed(&img.view(), &img.view(), 0.02, tick);
    /// assert_eq!(ns, [0, 0, 0, 1_000]);
    /// ```
    pub fn update_timed(&mut self, left: &ImageView<'_>, right: &ImageView<'_>, dt_s: f64, now_ns: impl Fn() -> u64) -> (StereoStates, [u64; 4]) {
        let mut states = StereoStates::default();
        let mut elapsed_ns = [0u64; 4];
        for role in Role::ALL {
            for view in View::ALL {
                let s = slot(role, view);
                if !self.active[s] {
                    continue;
                }
                if let Some(t) = self.trackers[s].as_mut() {
                    let image = match view {
                        View::Left => left,
                        View::Right => right,
                    };
                    let start_ns = now_ns();
                    states.states[s] = Some(t.update(image, dt_s));
                    elapsed_ns[s] = now_ns().saturating_sub(start_ns).max(1);
                }
            }
        }
        (states, elapsed_ns)
    }
}
