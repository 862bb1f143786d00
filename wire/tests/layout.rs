//! The byte offsets that `wire/README.md` documents for driver authors in other languages.

use std::mem::{align_of, offset_of, size_of};

use handeye_wire::*;

#[test]
fn stereo_header_offsets_match_the_readme() {
    assert_eq!((size_of::<StereoHeader>(), align_of::<StereoHeader>()), (48, 8));
    assert_eq!(offset_of!(StereoHeader, version), 0);
    assert_eq!(offset_of!(StereoHeader, pixel_format), 4);
    assert_eq!(offset_of!(StereoHeader, frame_id), 8);
    assert_eq!(offset_of!(StereoHeader, capture_time_ns), 16);
    assert_eq!(offset_of!(StereoHeader, publish_time_ns), 24);
    assert_eq!(offset_of!(StereoHeader, width), 32);
    assert_eq!(offset_of!(StereoHeader, height), 36);
    assert_eq!(offset_of!(StereoHeader, stride), 40);
    assert_eq!(offset_of!(StereoHeader, camera_count), 44);
}

#[test]
fn robot_state_offsets_match_the_readme() {
    assert_eq!((size_of::<RobotState>(), align_of::<RobotState>()), (88, 8));
    assert_eq!(offset_of!(RobotState, flags), 4);
    assert_eq!(offset_of!(RobotState, seq), 8);
    assert_eq!(offset_of!(RobotState, time_ns), 16);
    assert_eq!(offset_of!(RobotState, last_command_seq), 24);
    assert_eq!(offset_of!(RobotState, last_command_frame_id), 32);
    assert_eq!(offset_of!(RobotState, tool_pos_m), 40);
    assert_eq!(offset_of!(RobotState, tool_yaw_rad), 52);
    assert_eq!(offset_of!(RobotState, joints_rad), 56);
    assert_eq!(offset_of!(RobotState, gripper_width_m), 76);
    assert_eq!(offset_of!(RobotState, reject), 80);
    assert_eq!(offset_of!(RobotState, fault), 84);
}

#[test]
fn robot_command_offsets_match_the_readme() {
    assert_eq!((size_of::<RobotCommand>(), align_of::<RobotCommand>()), (56, 8));
    assert_eq!(offset_of!(RobotCommand, kind), 4);
    assert_eq!(offset_of!(RobotCommand, seq), 8);
    assert_eq!(offset_of!(RobotCommand, frame_id), 16);
    assert_eq!(offset_of!(RobotCommand, time_ns), 24);
    assert_eq!(offset_of!(RobotCommand, target_m), 32);
    assert_eq!(offset_of!(RobotCommand, yaw_rad), 44);
    assert_eq!(offset_of!(RobotCommand, speed_limit_mps), 48);
    assert_eq!(offset_of!(RobotCommand, gripper), 52);
}

#[test]
fn telemetry_offsets_match_the_readme() {
    assert_eq!((size_of::<Telemetry>(), align_of::<Telemetry>()), (600, 8));
    assert_eq!(offset_of!(Telemetry, phase), 4);
    assert_eq!(offset_of!(Telemetry, frame_id), 8);
    assert_eq!(offset_of!(Telemetry, time_ns), 16);
    assert_eq!(offset_of!(Telemetry, loop_ns), 24);
    assert_eq!(offset_of!(Telemetry, deadline_misses), 32);
    assert_eq!(offset_of!(Telemetry, tracker_updates), 40);
    assert_eq!(offset_of!(Telemetry, tracker_update_ns), 72);
    assert_eq!(offset_of!(Telemetry, tracker_state), 104);
    assert_eq!(offset_of!(Telemetry, tracker_confidence), 120);
    assert_eq!(offset_of!(Telemetry, tracker_corners_px), 136);
    assert_eq!(offset_of!(Telemetry, servo_error), 392);
    assert_eq!(offset_of!(Telemetry, servo_steps), 416);
    assert_eq!(offset_of!(Telemetry, planning), 420);
    assert_eq!(offset_of!(Telemetry, reason), 424);
    assert_eq!(offset_of!(Telemetry, dropped_frames), 520);
    assert_eq!(offset_of!(Telemetry, pointing_update_ns), 528);
    assert_eq!(offset_of!(Telemetry, pointing_state), 536);
    assert_eq!(offset_of!(Telemetry, pointing_frame), 540);
    assert_eq!(offset_of!(Telemetry, pointing_point_m), 544);
    assert_eq!(offset_of!(Telemetry, pointing_sigma_m), 552);
    assert_eq!(offset_of!(Telemetry, pointing_crossing_rad), 556);
    assert_eq!(offset_of!(Telemetry, pointing_tip_px), 560);
    assert_eq!(offset_of!(Telemetry, pointing_line_px), 576);
}
