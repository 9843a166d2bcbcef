//! The forward pass with a fixed room for intersections (what training loops record without
//! reading anything back): the status words report the count and any overflow, and with
//! enough room the images equal those of the self-sizing `forward`.

mod common;

use cocog_engine::{Batch, Renderer, View, Workspace};
use common::{gpu, random_scene, test_camera};

#[test]
fn status_reports_overflow_and_enough_room_renders_exactly() {
    let Some(ctx) = gpu() else { return };
    let cam = test_camera(40, 30, 0.3);
    let g = random_scene(60, 1, 5, &cam);
    let view = View {
        gaussians: &g,
        camera: &cam,
        background: [0.1, 0.2, 0.3],
    };
    let batch = Batch::from_views(ctx, &[view]).unwrap();
    let renderer = Renderer::new(ctx);
    let reference = renderer.forward(ctx, &batch).unwrap();
    let k = reference.num_intersections;
    assert!(k > 10, "the scene must cover several tiles: {k}");
    let want = reference.read_images(ctx, &batch).unwrap();
    let mut ws = Workspace::default();
    for (room, overflowed) in [(k / 2, 1), (k - 1, 1), (k, 0), (2 * k, 0)] {
        let mut rec = ctx.recorder();
        let state = renderer.encode_forward(&mut rec, &mut ws, &batch, room);
        rec.submit();
        let status: Vec<u32> = ctx.read(&state.status, 2).unwrap();
        assert_eq!(status, [overflowed, k], "room {room}");
        if overflowed == 0 {
            // Same workspace reused across passes: stale contents must not leak in.
            assert_eq!(state.read_images(ctx, &batch).unwrap(), want, "room {room}");
        }
    }
}
