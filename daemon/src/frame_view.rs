//! Validated client planes → the estimator's borrowed frame view (no copy).

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
        }),
    }
}
