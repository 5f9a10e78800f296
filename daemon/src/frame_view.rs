//! Validated client planes → the estimator's borrowed frame view (no copy;
//! an instance plane and its class table are passed through as they are).

use fusepose_client::{ColorFormat, DepthData, FramePlanes, LabelData};
use fusepose_estimator::{DepthPlane, FrameView, LabelPlane};
use fusepose_scene::Intrinsics;

pub fn to_frame_view<'a>(planes: &FramePlanes<'a>) -> FrameView<'a> {
    let h = &planes.header;
    FrameView {
        intrinsics: Intrinsics { fx: h.fx, fy: h.fy, cx: h.cx, cy: h.cy, width: h.width, height: h.height },
        color_format: match planes.color_format {
            ColorFormat::Rgb8 => fusepose_estimator::ColorFormat::Rgb8,
            ColorFormat::Bgr8 => fusepose_estimator::ColorFormat::Bgr8,
        },
        color: planes.color,
        depth: match planes.depth {
            DepthData::U16 { data, scale } => DepthPlane::U16 { data, scale },
            DepthData::F32(data) => DepthPlane::F32(data),
        },
        labels: planes.labels.map(|l| match l {
            LabelData::U8(data) => LabelPlane::U8(data),
            LabelData::U16(data) => LabelPlane::U16(data),
            LabelData::Instances { ids, classes } => LabelPlane::Instances { ids, classes },
        }),
    }
}

#[cfg(test)]
mod tests {
    use fusepose_client::{FrameHeader, FrameLayout, LabelFormat, decode_frame};
    use fusepose_estimator::LabelPlane;

    #[test]
    fn an_instance_plane_reaches_the_estimator_as_is() {
        let layout = FrameLayout {
            width: 4,
            height: 2,
            labels: Some(LabelFormat::InstanceU16 { max_instances: 2 }),
            ..FrameLayout::vga_rgbd()
        };
        // An 8-byte aligned payload, as iceoryx2 gives one.
        #[repr(align(8))]
        struct Payload([u8; 64]);
        let mut payload = Payload([0; 64]);
        let bytes = &mut payload.0;
        assert_eq!(layout.payload_len(), 62);
        let [_, depth, ids] = layout.planes();
        let table = layout.instance_classes();
        bytes[depth.offset as usize] = 1; // one depth reading
        bytes[ids.offset as usize + 2] = 2; // pixel 1: instance 2
        bytes[table.offset as usize + 4] = 7; // instance 2: class 7
        let header = FrameHeader { fx: 100.0, fy: 100.0, cx: 2.0, cy: 1.0, ..layout.header(1) };
        let planes = decode_frame(&header, &bytes[..layout.payload_len()], Some(1)).unwrap();
        let view = super::to_frame_view(&planes);
        let Some(LabelPlane::Instances { ids, classes }) = view.labels else { panic!("{:?}", view.labels) };
        assert_eq!((ids.len(), ids[1], classes), (8, 2, &[0, 0, 7][..]));
        assert_eq!(view.labels.unwrap().class_at(1), 7);
        assert!(view.validate().is_ok() && view.check_content(7).is_ok());
    }
}
