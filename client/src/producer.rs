//! The camera side: loan a frame in shared memory, fill its planes in place, send.

use core::mem::MaybeUninit;

use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::prelude::*;
use iceoryx2::sample_mut_uninit::SampleMutUninit;

use crate::services::CameraServices;
use crate::{ClientError, DepthFormat, FrameHeader, FrameLayout, Ipc, LabelFormat, monotonic_ns};

/// Publishes frames of one camera.
pub struct Producer {
    services: CameraServices,
    publisher: Publisher<ipc::Service, [u8], FrameHeader>,
    notifier: Notifier<ipc::Service>,
    layout: FrameLayout,
    next_sequence: u64,
}

/// Mutable depth plane of a loaned frame.
pub enum DepthMut<'a> {
    U16(&'a mut [u16]),
    F32(&'a mut [f32]),
}

/// Mutable label plane of a loaned frame.
pub enum LabelsMut<'a> {
    /// Class ids (0 = background).
    U8(&'a mut [u8]),
    /// Class ids (0 = background).
    U16(&'a mut [u16]),
    /// [`LabelFormat::InstanceU16`]: an instance id per pixel (0 = background,
    /// else 1..=`max_instances`) and the class of each instance: set
    /// `classes[id]` for every id in use (entry 0 is unused; write 0).
    Instances { ids: &'a mut [u16], classes: &'a mut [u16] },
}

/// All planes of a loaned frame at once (disjoint borrows).
pub struct PlanesMut<'a> {
    /// width * height * 3 bytes in the layout's colour order.
    pub color: &'a mut [u8],
    pub depth: DepthMut<'a>,
    pub labels: Option<LabelsMut<'a>>,
}

/// A frame loaned in shared memory. Fill the planes (every byte: the chunk
/// holds whatever an earlier frame left there), set time and intrinsics, [`FrameWriter::send`].
pub struct FrameWriter<'p> {
    producer: &'p mut Producer,
    sample: SampleMutUninit<ipc::Service, [MaybeUninit<u8>], FrameHeader>,
}

impl Producer {
    /// Creates the publisher of camera `camera` for frames of `layout`.
    pub fn create(ipc: &Ipc, camera: &str, layout: FrameLayout) -> Result<Self, ClientError> {
        layout.validate().map_err(ClientError::Layout)?;
        let services = CameraServices::open(ipc, camera)?;
        let publisher = services.frame_publisher(layout.payload_len())?;
        let notifier = services.frame_notifier()?;
        Ok(Self { services, publisher, notifier, layout, next_sequence: 0 })
    }

    pub fn layout(&self) -> &FrameLayout {
        &self.layout
    }

    pub fn camera_id(&self) -> u32 {
        self.services.camera_id
    }

    /// Sequence number the next frame will carry.
    pub fn next_sequence(&self) -> u64 {
        self.next_sequence
    }

    /// Starts the sequence at `sequence` (e.g. to continue after a restart).
    pub fn set_next_sequence(&mut self, sequence: u64) {
        self.next_sequence = sequence;
    }

    /// Loans the next frame in shared memory; the header is filled from the
    /// layout, the sequence and the current time (override with the setters).
    pub fn loan(&mut self) -> Result<FrameWriter<'_>, ClientError> {
        let mut sample = self
            .publisher
            .loan_slice_uninit(self.layout.payload_len())
            .map_err(|e| ClientError::transfer(&self.services.frames_name, "loan", &e))?;
        let mut header = self.layout.header(self.services.camera_id);
        header.sequence = self.next_sequence;
        header.capture_time_ns = monotonic_ns();
        *sample.user_header_mut() = header;
        Ok(FrameWriter { producer: self, sample })
    }

    /// Sends `payload` with `header` exactly as given, without any checks (and
    /// without touching the sequence counter): for conformance tests of receivers.
    pub fn send_raw(&mut self, header: FrameHeader, payload: &[u8]) -> Result<(), ClientError> {
        let service = &self.services.frames_name;
        if payload.len() > self.layout.payload_len() {
            return Err(ClientError::Layout(format!(
                "raw payload of {} bytes exceeds the {}-byte frame size",
                payload.len(),
                self.layout.payload_len()
            )));
        }
        let mut sample =
            self.publisher.loan_slice_uninit(payload.len()).map_err(|e| ClientError::transfer(service, "loan", &e))?;
        *sample.user_header_mut() = header;
        let sample = sample.write_from_slice(payload);
        sample.send().map_err(|e| ClientError::Transfer {
            service: service.clone(),
            operation: "send",
            detail: format!("{e:?}"),
        })?;
        self.notify()
    }

    fn notify(&self) -> Result<(), ClientError> {
        self.notifier.notify().map(|_| ()).map_err(|e| ClientError::Transfer {
            service: self.services.frames_name.clone(),
            operation: "notify",
            detail: format!("{e:?}"),
        })
    }
}

fn cast_mut<T: bytemuck::Pod>(bytes: &mut [u8]) -> &mut [T] {
    // Plane offsets are multiples of 8 from an 8-byte aligned payload (FrameLayout::planes).
    bytemuck::cast_slice_mut(bytes)
}

impl FrameWriter<'_> {
    pub fn header(&self) -> &FrameHeader {
        self.sample.user_header()
    }

    /// The header, for fields the setters do not cover. Keep the plane fields as they are.
    pub fn header_mut(&mut self) -> &mut FrameHeader {
        self.sample.user_header_mut()
    }

    /// Capture time, `CLOCK_MONOTONIC` ns (default: when the frame was loaned).
    pub fn set_capture_time_ns(&mut self, t: u64) -> &mut Self {
        self.sample.user_header_mut().capture_time_ns = t;
        self
    }

    /// Pinhole intrinsics, pixels.
    pub fn set_intrinsics(&mut self, fx: f64, fy: f64, cx: f64, cy: f64) -> &mut Self {
        let h = self.sample.user_header_mut();
        (h.fx, h.fy, h.cx, h.cy) = (fx, fy, cx, cy);
        self
    }

    /// The whole payload as bytes.
    fn payload_bytes(&mut self) -> &mut [u8] {
        let payload = self.sample.payload_mut();
        // SAFETY: the payload lies in a MAP_SHARED shared-memory mapping whose
        // bytes are always initialised (zero-filled by the kernel at creation,
        // then written by earlier frames), and every bit pattern is a valid u8.
        // The producer overwrites every plane byte before sending.
        unsafe { core::slice::from_raw_parts_mut(payload.as_mut_ptr().cast::<u8>(), payload.len()) }
    }

    /// Mutable views of the colour, depth and (when the layout has them) label
    /// planes; with instance labels also the instance class table.
    pub fn planes_mut(&mut self) -> PlanesMut<'_> {
        let layout = self.producer.layout;
        let [color, depth, labels] = layout.planes();
        let table = layout.instance_classes();
        let bytes = self.payload_bytes();
        let (head, rest) = bytes.split_at_mut(depth.offset as usize);
        let color_plane = &mut head[..color.len as usize];
        let (depth_bytes, tail) = rest.split_at_mut(depth.len as usize);
        let depth_plane = match layout.depth_format {
            DepthFormat::U16 => DepthMut::U16(cast_mut(depth_bytes)),
            DepthFormat::F32 => DepthMut::F32(cast_mut(depth_bytes)),
        };
        let label_plane = layout.labels.map(|format| {
            let start = (labels.offset as u64 - depth.end()) as usize;
            let (label_bytes, after) = tail[start..].split_at_mut(labels.len as usize);
            match format {
                LabelFormat::U8 => LabelsMut::U8(label_bytes),
                LabelFormat::U16 => LabelsMut::U16(cast_mut(label_bytes)),
                LabelFormat::InstanceU16 { .. } => {
                    let start = (table.offset as u64 - labels.end()) as usize;
                    let classes = &mut after[start..start + table.len as usize];
                    LabelsMut::Instances { ids: cast_mut(label_bytes), classes: cast_mut(classes) }
                }
            }
        });
        PlanesMut { color: color_plane, depth: depth_plane, labels: label_plane }
    }

    /// Publishes the frame, wakes the daemon and returns the frame's sequence number.
    pub fn send(mut self) -> Result<u64, ClientError> {
        // Zero the padding between planes so no stale bytes travel.
        let [color, depth, labels] = self.producer.layout.planes();
        let table = self.producer.layout.instance_classes();
        let bytes = self.payload_bytes();
        bytes[color.len as usize..depth.offset as usize].fill(0);
        if labels.len > 0 {
            bytes[depth.end() as usize..labels.offset as usize].fill(0);
        }
        if table.len > 0 {
            bytes[labels.end() as usize..table.offset as usize].fill(0);
        }
        let sequence = self.sample.user_header().sequence;
        // SAFETY: see `payload_bytes`: the bytes are initialised.
        let sample = unsafe { self.sample.assume_init() };
        let producer = self.producer;
        sample.send().map_err(|e| ClientError::Transfer {
            service: producer.services.frames_name.clone(),
            operation: "send",
            detail: format!("{e:?}"),
        })?;
        producer.next_sequence = sequence.wrapping_add(1);
        producer.notify()?;
        Ok(sequence)
    }
}
