//! Scenes built from the body model's renderer: a room (floor, back wall, optionally a
//! side wall), the body standing on the floor, and clutter.

use super::*;
use crate::body::BodyModel;
use std::sync::Arc;

/// A room seen by the ITOP-like camera: the floor at `floor` metres below the camera
/// (y down), a back wall at `wall` metres, optionally a side wall at x = `side`.
struct Room {
    camera: Camera,
    floor: f64,
    wall: f64,
    side: Option<f64>,
}

impl Room {
    fn new() -> Self {
        Room {
            camera: Camera::itop(),
            floor: 1.0,
            wall: 5.0,
            side: None,
        }
    }

    /// Depth of the empty room (nearest of the planes along each ray).
    fn depth(&self) -> Vec<f32> {
        let c = &self.camera;
        let mut out = vec![0.0f32; c.width * c.height];
        for row in 0..c.height {
            for col in 0..c.width {
                let rx = (col as f64 - c.cx) / c.fx;
                let ry = (row as f64 - c.cy) / c.fy;
                let mut z = self.wall;
                if ry > 0.0 {
                    z = z.min(self.floor / ry);
                }
                if let Some(s) = self.side {
                    if rx * s > 0.0 {
                        z = z.min(s / rx);
                    }
                }
                out[row * c.width + col] = z as f32;
            }
        }
        out
    }
}

/// The body's standing pose with its feet on a floor `floor` metres below the camera, its
/// hip `x` metres right of the camera axis and `z` metres away.
fn standing(model: &BodyModel, floor: f64, x: f64, z: f64) -> crate::body::Pose {
    let mut pose = BodyModel::neutral_pose();
    pose[0] = x;
    pose[2] = z;
    let joints = model.joints(&pose);
    let lowest = joints.iter().map(|j| j[1]).fold(f64::MIN, f64::max);
    // Ankles are about 8 cm above the soles.
    pose[1] = floor - lowest - 0.08;
    pose
}

/// Pastes the body standing on `room`'s floor, its hip at (`x`, `z`), over `scene`;
/// returns the body's pixels.
fn paste_standing(scene: &mut [f32], room: &Room, model: &BodyModel, x: f64, z: f64) -> Vec<bool> {
    let pose = standing(model, room.floor, x, z);
    let (body, _) = model.render_depth(&pose, &room.camera);
    paste(scene, &body)
}

/// Pastes a rendered body (depth 0 = none) over `scene`; returns the body's pixels.
fn paste(scene: &mut [f32], body: &[f32]) -> Vec<bool> {
    let mut mask = vec![false; scene.len()];
    for ((s, &b), m) in scene.iter_mut().zip(body).zip(mask.iter_mut()) {
        if b > 0.0 && b < *s {
            *s = b;
            *m = true;
        }
    }
    mask
}

/// A box (axis-aligned in the camera frame) pasted over `scene`: its near face at depth
/// `z0`, spanning x in `xs` and y in `ys` (camera frame, metres).
fn paste_box(scene: &mut [f32], camera: &Camera, xs: (f64, f64), ys: (f64, f64), z0: f64) {
    for row in 0..camera.height {
        for col in 0..camera.width {
            let rx = (col as f64 - camera.cx) / camera.fx;
            let ry = (row as f64 - camera.cy) / camera.fy;
            let (x, y) = (rx * z0, ry * z0);
            let i = row * camera.width + col;
            if x >= xs.0 && x <= xs.1 && y >= ys.0 && y <= ys.1 && (z0 as f32) < scene[i] {
                scene[i] = z0 as f32;
            }
        }
    }
}

fn iou(a: &[bool], b: &[bool]) -> f64 {
    let inter = a.iter().zip(b).filter(|(&x, &y)| x && y).count();
    let union = a.iter().zip(b).filter(|(&x, &y)| x || y).count();
    inter as f64 / union.max(1) as f64
}

fn segment(scene: &[f32], camera: &Camera, hint: Option<&SegmentHint>) -> Result<Segmentation> {
    let view = DepthView::new(scene, camera.height, camera.width, "depth").unwrap();
    segment_person(&view, camera, None, &SegmentConfig::default(), hint)
}

#[test]
fn a_person_in_a_room_is_found_without_a_background() {
    let room = Room::new();
    let model = BodyModel::new(1.75).unwrap();
    let mut scene = room.depth();
    let truth = paste_standing(&mut scene, &room, &model, 0.2, 3.0);
    let seg = segment(&scene, &room.camera, None).unwrap();
    assert_eq!(seg.method, Method::Planes);
    assert_eq!(seg.planes.len(), 2, "floor and wall: {:?}", seg.planes);
    let floor = seg
        .planes
        .iter()
        .find(|p| p.normal[1] > 0.9)
        .expect("a floor");
    assert!((floor.offset - room.floor).abs() < 0.01, "{floor:?}");
    let wall = seg
        .planes
        .iter()
        .find(|p| p.normal[2] > 0.9)
        .expect("a wall");
    assert!((wall.offset - room.wall).abs() < 0.02, "{wall:?}");
    let score = iou(&seg.mask, &truth);
    assert!(score > 0.97, "IoU {score}");
    assert!(
        seg.person.height > 1.5 && seg.person.height < 1.9,
        "{:?}",
        seg.person
    );
    assert!(seg.others.is_empty(), "{:?}", seg.others);
}

#[test]
fn clutter_beside_the_person_is_left_out() {
    let mut room = Room::new();
    room.side = Some(-2.0); // a side wall to the left
    let model = BodyModel::new(1.75).unwrap();
    let mut scene = room.depth();
    // A box 0.5 m on a side standing on the floor to the person's right, and a tall
    // narrow cabinet behind-left.
    paste_box(
        &mut scene,
        &room.camera,
        (0.7, 1.2),
        (room.floor - 0.5, room.floor),
        2.8,
    );
    paste_box(
        &mut scene,
        &room.camera,
        (-1.4, -1.0),
        (room.floor - 1.2, room.floor),
        3.6,
    );
    let truth = paste_standing(&mut scene, &room, &model, 0.0, 3.0);
    let seg = segment(&scene, &room.camera, None).unwrap();
    assert_eq!(seg.planes.len(), 3, "{:?}", seg.planes);
    let score = iou(&seg.mask, &truth);
    assert!(score > 0.95, "IoU {score}");
}

#[test]
fn a_person_touching_the_wall_is_found() {
    let mut room = Room::new();
    room.wall = 3.25;
    let model = BodyModel::new(1.75).unwrap();
    let mut scene = room.depth();
    let truth = paste_standing(&mut scene, &room, &model, 0.0, 3.1);
    let seg = segment(&scene, &room.camera, None).unwrap();
    let score = iou(&seg.mask, &truth);
    // The back of the body within the sensor's tolerance of the wall goes with it.
    assert!(score > 0.85, "IoU {score}");
}

#[test]
fn two_people_the_nearer_is_chosen_then_the_tracked_one_is_kept() {
    let room = Room::new();
    let model = BodyModel::new(1.75).unwrap();
    let mut scene = room.depth();
    let truth_far = paste_standing(&mut scene, &room, &model, -0.7, 3.6);
    let truth_near = paste_standing(&mut scene, &room, &model, 0.7, 2.6);
    let seg = segment(&scene, &room.camera, None).unwrap();
    assert!(iou(&seg.mask, &truth_near) > 0.95);
    assert_eq!(seg.others.len(), 1, "the other person is reported");
    // A video that followed the far person keeps it.
    let hint = SegmentHint {
        planes: seg.planes.clone(),
        centroid: Some(seg.others[0].centroid),
        background: None,
    };
    let followed = segment(&scene, &room.camera, Some(&hint)).unwrap();
    assert!(iou(&followed.mask, &truth_far) > 0.9);
}

#[test]
fn an_empty_room_has_no_body_and_says_what_it_saw() {
    let room = Room::new();
    let scene = room.depth();
    let err = segment(&scene, &room.camera, None).unwrap_err();
    let Error::NoBody(msg) = err else {
        panic!("expected NoBody, got {err:?}")
    };
    assert!(msg.contains("2 support planes"), "{msg}");
}

#[test]
fn the_previous_planes_are_reused() {
    let room = Room::new();
    let model = BodyModel::new(1.75).unwrap();
    let mut scene = room.depth();
    let truth = paste_standing(&mut scene, &room, &model, 0.0, 3.0);
    let first = segment(&scene, &room.camera, None).unwrap();
    let next = segment(&scene, &room.camera, Some(&first.hint())).unwrap();
    assert_eq!(next.planes.len(), first.planes.len());
    for (a, b) in next.planes.iter().zip(&first.planes) {
        assert!((a.offset - b.offset).abs() < 1e-3);
    }
    assert!(iou(&next.mask, &truth) > 0.97);
}

#[test]
fn a_lone_body_without_planes_is_found() {
    // Real recordings often come with the background already removed.
    let camera = Camera::itop();
    let model = BodyModel::new(1.75).unwrap();
    let pose = standing(&model, 1.0, 0.0, 2.5);
    let (body, _) = model.render_depth(&pose, &camera);
    let truth: Vec<bool> = body.iter().map(|&z| z > 0.0).collect();
    let seg = segment(&body, &camera, None).unwrap();
    assert!(seg.planes.is_empty());
    assert!(iou(&seg.mask, &truth) > 0.99);
}

#[test]
fn a_background_frame_is_used_when_given() {
    let room = Room::new();
    let model = BodyModel::new(1.75).unwrap();
    let bg = room.depth();
    let mut scene = bg.clone();
    let truth = paste_standing(&mut scene, &room, &model, 0.0, 3.0);
    let c = &room.camera;
    let view = DepthView::new(&scene, c.height, c.width, "depth").unwrap();
    let bgv = DepthView::new(&bg, c.height, c.width, "background").unwrap();
    let seg = segment_person(&view, c, Some(&bgv), &SegmentConfig::default(), None).unwrap();
    assert_eq!(seg.method, Method::Background);
    assert!(iou(&seg.mask, &truth) > 0.95);
}

#[test]
fn a_camera_of_another_size_is_refused() {
    let camera = Camera::itop();
    let depth = vec![1.0f32; 12];
    let view = DepthView::new(&depth, 3, 4, "depth").unwrap();
    let err = segment_person(&view, &camera, None, &SegmentConfig::default(), None);
    assert!(matches!(err, Err(Error::InvalidArgument { .. })));
}

/// The hint of a video whose learned background is `learned`.
fn learned_hint(learned: Vec<f32>) -> SegmentHint {
    SegmentHint {
        background: Some(Arc::new(learned)),
        ..SegmentHint::default()
    }
}

#[test]
fn a_learned_background_decides_the_pixels_it_knows_and_planes_the_rest() {
    let mut room = Room::new();
    room.side = Some(-2.0);
    let model = BodyModel::new(1.75).unwrap();
    let mut empty = room.depth();
    // Clutter: a box on the floor and a tall cabinet, both part of the learned scene.
    paste_box(&mut empty, &room.camera, (0.7, 1.2), (0.5, 1.0), 2.8);
    paste_box(&mut empty, &room.camera, (-1.4, -1.0), (-0.2, 1.0), 3.6);
    let mut scene = empty.clone();
    let truth = paste_standing(&mut scene, &room, &model, 0.0, 3.0);
    // The person has stood still with its left half all along: unknown around there.
    let w = room.camera.width;
    let person: Vec<usize> = (0..truth.len()).filter(|&i| truth[i]).collect();
    let rows = person.iter().map(|&i| i / w);
    let (top, bottom) = (rows.clone().min().unwrap(), rows.max().unwrap());
    let cols = person.iter().map(|&i| i % w);
    let (left, right) = (cols.clone().min().unwrap(), cols.max().unwrap());
    let mut learned = empty.clone();
    for (i, b) in learned.iter_mut().enumerate() {
        let (r, c) = (i / w, i % w);
        if r + 4 >= top && r <= bottom + 4 && c + 4 >= left && c <= (left + right) / 2 {
            *b = 0.0;
        }
    }
    assert!(learned.iter().zip(&truth).any(|(&b, &t)| t && b == 0.0));
    assert!(learned.iter().zip(&truth).any(|(&b, &t)| t && b > 0.0));
    let seg = segment(&scene, &room.camera, Some(&learned_hint(learned.clone()))).unwrap();
    assert_eq!(seg.method, Method::Learned);
    assert_eq!(seg.method.name(), "learned");
    let score = iou(&seg.mask, &truth);
    assert!(score > 0.95, "IoU {score}");
    assert!(seg.others.is_empty(), "{:?}", seg.others);
    // A learned background of another size is refused, naming it.
    let err = segment(&scene, &room.camera, Some(&learned_hint(vec![3.0; 7]))).unwrap_err();
    assert!(err.to_string().contains("hint.background"), "{err}");
}

#[test]
fn a_person_touching_the_wall_is_cut_closer_with_a_learned_background() {
    let mut room = Room::new();
    room.wall = 3.25;
    let model = BodyModel::new(1.75).unwrap();
    let empty = room.depth();
    let mut scene = empty.clone();
    let truth = paste_standing(&mut scene, &room, &model, 0.0, 3.1);
    let planes = iou(&segment(&scene, &room.camera, None).unwrap().mask, &truth);
    let seg = segment(&scene, &room.camera, Some(&learned_hint(empty))).unwrap();
    let learned = iou(&seg.mask, &truth);
    assert!(learned >= planes && learned > 0.85, "{learned} vs {planes}");
}
