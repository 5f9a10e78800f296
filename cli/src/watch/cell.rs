//! `fusepose watch --cell`: the cell's objects (every camera's poses in the
//! cell frame, one entry per physical object) as text or JSON lines.

use std::time::{Duration, Instant};

use fusepose_client::{CellConsumer, CellObject, CellPoseMessage, Ipc, monotonic_ns};

use super::{object_name, pose_text};

fn text(msg: &CellPoseMessage) -> String {
    let mut out = format!(
        "cell {:>6}  {} camera(s)  {} object(s){}",
        msg.sequence,
        msg.camera_count,
        msg.object_count,
        if msg.truncated != 0 { " (truncated)" } else { "" }
    );
    for o in msg.objects() {
        let cams: Vec<String> = o.views().iter().map(|v| format!("{:08x}", v.camera_id)).collect();
        out.push_str(&format!(
            "\n  {:<16} {}  conf {:.2}  views {} [{}]  spread {:.1} mm",
            object_name(o.class_id),
            pose_text(o.translation_m, o.quaternion),
            o.confidence,
            o.view_count,
            cams.join(" "),
            o.spread_m * 1e3
        ));
    }
    out
}

fn json_object(o: &CellObject) -> String {
    let t = o.translation_m.map(|v| v * 1e3);
    let q = o.quaternion;
    let views: Vec<String> = o
        .views()
        .iter()
        .map(|v| {
            format!(
                "{{\"camera_id\":{},\"instance_id\":{},\"frame_sequence\":{},\"capture_time_ns\":{},\"confidence\":{:.4},\"flags\":{},\"offset_mm\":{:.3}}}",
                v.camera_id, v.instance_id, v.frame_sequence, v.capture_time_ns, v.confidence, v.flags, v.offset_m * 1e3
            )
        })
        .collect();
    format!(
        "{{\"class_id\":{},\"name\":{:?},\"xyz_mm\":[{:.3},{:.3},{:.3}],\"quaternion_xyzw\":[{:.6},{:.6},{:.6},{:.6}],\"confidence\":{:.4},\"flags\":{},\"spread_mm\":{:.3},\"view_count\":{},\"newest_capture_time_ns\":{},\"oldest_capture_time_ns\":{},\"views\":[{}]}}",
        o.class_id,
        object_name(o.class_id),
        t[0],
        t[1],
        t[2],
        q[0],
        q[1],
        q[2],
        q[3],
        o.confidence,
        o.flags,
        o.spread_m * 1e3,
        o.view_count,
        o.newest_capture_time_ns,
        o.oldest_capture_time_ns,
        views.join(",")
    )
}

fn json(msg: &CellPoseMessage) -> String {
    let objects: Vec<String> = msg.objects().iter().map(json_object).collect();
    format!(
        "{{\"cell_sequence\":{},\"trigger_camera_id\":{},\"camera_count\":{},\"truncated\":{},\"published_time_ns\":{},\"age_ms\":{:.3},\"objects\":[{}]}}",
        msg.sequence,
        msg.trigger_camera_id,
        msg.camera_count,
        msg.truncated != 0,
        msg.published_time_ns,
        monotonic_ns().saturating_sub(msg.published_time_ns) as f64 / 1e6,
        objects.join(",")
    )
}

/// Prints cell messages until `count` or `idle` (as `watch` does for one camera).
pub fn run(ipc: &Ipc, json_lines: bool, count: Option<u64>, idle: Option<Duration>) -> anyhow::Result<()> {
    let mut consumer = CellConsumer::open(ipc)?;
    let (mut seen, mut last) = (0u64, Instant::now());
    while count.is_none_or(|n| seen < n) {
        match consumer.wait(Duration::from_millis(500))? {
            Some(msg) => {
                last = Instant::now();
                seen += 1;
                println!("{}", if json_lines { json(&msg) } else { text(&msg) });
            }
            None => {
                if idle.is_some_and(|d| last.elapsed() >= d) {
                    anyhow::bail!("no cell message for {:?}", idle.unwrap_or_default());
                }
            }
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use fusepose_client::{CellView, MAX_CELL_VIEWS};

    use super::*;

    #[test]
    fn json_lists_every_view_with_its_capture_time() {
        let mut views = [CellView::default(); MAX_CELL_VIEWS];
        views[0] = CellView { camera_id: 7, capture_time_ns: 123, frame_sequence: 9, ..CellView::default() };
        views[1] = CellView { camera_id: 8, capture_time_ns: 120, ..CellView::default() };
        let o =
            CellObject { class_id: 1, view_count: 2, quaternion: [0.0, 0.0, 0.0, 1.0], views, ..CellObject::default() };
        let j = json_object(&o);
        assert!(
            j.contains(r#""view_count":2"#)
                && j.contains(r#""camera_id":7,"instance_id":0,"frame_sequence":9,"capture_time_ns":123"#),
            "{j}"
        );
        assert!(j.contains(r#""camera_id":8"#) && !j.contains(r#""camera_id":0"#), "only the listed views: {j}");
    }
}
