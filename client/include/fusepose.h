/*
 * fusepose.h - the fusepose wire types for C and C++ (C99, no dependencies).
 *
 * Hand-written mirror of the #[repr(C)] types in fusepose-client
 * (client/src/frame_header.rs, pose_message.rs, stats.rs, cell_message.rs). The Rust test
 * client/tests/c_header.rs compiles a C program against this header and
 * compares every struct size, every field offset and size, every field name
 * and every constant with the Rust definitions, so the two cannot drift apart
 * unnoticed. See docs/PROTOCOL.md for the full contract.
 *
 * Conventions: little-endian; lengths in metres; times in nanoseconds of
 * CLOCK_MONOTONIC; camera optical frame (x right, y down, z forward);
 * quaternions [x, y, z, w] mapping object -> camera coordinates.
 *
 * iceoryx2 services of camera <name> (all carry the attribute
 * "fusepose.wire_version" = FUSEPOSE_WIRE_VERSION as a decimal string):
 *   fusepose/camera/<name>/frames  pub-sub, payload [u8] slice, user header fp_frame_header
 *                                  (type name "fusepose::FrameHeader"), plus an event service
 *   fusepose/camera/<name>/poses   pub-sub, payload fp_pose_message ("fusepose::PoseMessage"),
 *                                  plus an event service of the same name
 *   fusepose/camera/<name>/stats   request-response fp_stats_request -> fp_stats_snapshot
 * and of the cell (all cameras of one daemon, in the cell frame):
 *   fusepose/cell/poses            pub-sub, payload fp_cell_pose_message ("fusepose::CellPoseMessage"),
 *                                  plus an event service of the same name
 */
#ifndef FUSEPOSE_H
#define FUSEPOSE_H

#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

/* Version of every wire type; bumped on any layout change. */
#define FUSEPOSE_WIRE_VERSION 3
/* b"FPFR" read as a little-endian u32: first field of every frame header. */
#define FUSEPOSE_FRAME_MAGIC 0x52465046u
/* Most object poses in one pose message. */
#define FUSEPOSE_MAX_OBJECTS 32
/* Largest accepted image side, pixels. */
#define FUSEPOSE_MAX_IMAGE_SIDE 4096
/* Pipeline stages timed per frame, and stages + end-to-end in stats arrays. */
#define FUSEPOSE_STAGE_COUNT 6
#define FUSEPOSE_TIMELINE_COUNT 7
/* Number of invalid-frame reason codes (size of fp_stats_snapshot.invalid_by_reason). */
#define FUSEPOSE_INVALID_REASON_COUNT 29

/* fp_frame_header.color_format */
#define FUSEPOSE_COLOR_RGB8 1
#define FUSEPOSE_COLOR_BGR8 2
/* fp_frame_header.depth_format: u16 units times depth_scale metres, or f32 metres; 0 = no reading. */
#define FUSEPOSE_DEPTH_U16 1
#define FUSEPOSE_DEPTH_F32 2
/* fp_frame_header.label_format: per-pixel class id (1, 2) or instance id (3), 0 = background.
 * With FUSEPOSE_LABELS_INSTANCE_U16, fp_frame_header.instance_classes holds instance_count + 1
 * uint16_t class ids, entry [id] the class of instance id (entry 0 unused, write 0). */
#define FUSEPOSE_LABELS_U8 1
#define FUSEPOSE_LABELS_U16 2
#define FUSEPOSE_LABELS_INSTANCE_U16 3

/* fp_pose_message.status bits */
#define FUSEPOSE_STATUS_OK (1u << 0)
#define FUSEPOSE_STATUS_INVALID_FRAME (1u << 1)
#define FUSEPOSE_STATUS_DEADLINE_MISSED (1u << 2)
#define FUSEPOSE_STATUS_DEGRADED (1u << 3)
#define FUSEPOSE_STATUS_ESTIMATOR_FAILED (1u << 4)

/* fp_object_pose.flags bits (the others are 0) */
#define FUSEPOSE_POSE_VERIFIED (1u << 0)              /* passed verification (scores are NaN when it did not run) */
#define FUSEPOSE_POSE_FROM_INSTANCE_LABELS (1u << 1)  /* mask from the frame's own instance-label plane */
#define FUSEPOSE_POSE_CONFIRMED (1u << 2)             /* a pose of its class lay near it in the last frame that looked at the class */

/* Cell poses: most objects per message, most views listed per object. */
#define FUSEPOSE_MAX_CELL_OBJECTS 64
#define FUSEPOSE_MAX_CELL_VIEWS 4
/* fp_cell_object.flags bits */
#define FUSEPOSE_CELL_VERIFIED (1u << 0)                 /* every listed view passed verification */
#define FUSEPOSE_CELL_ROTATION_FROM_BEST_VIEW (1u << 1)  /* fusion "mean": views too far in rotation left out */

/* Stage indices into stage_ns and the stats arrays (end-to-end is index 6 in stats). */
#define FUSEPOSE_STAGE_INGEST 0
#define FUSEPOSE_STAGE_SEGMENTATION 1
#define FUSEPOSE_STAGE_SAMPLING 2
#define FUSEPOSE_STAGE_NETWORK 3
#define FUSEPOSE_STAGE_REFINE 4
#define FUSEPOSE_STAGE_PUBLISH 5

/* Where one plane lies in the frame payload, bytes from the payload start. */
typedef struct fp_plane_ref {
    uint32_t offset;
    uint32_t len;
} fp_plane_ref;

/* User header of every frame sample (128 bytes, no padding). */
typedef struct fp_frame_header {
    uint32_t magic;           /* FUSEPOSE_FRAME_MAGIC */
    uint16_t format_version;  /* FUSEPOSE_WIRE_VERSION */
    uint16_t header_size;     /* sizeof(fp_frame_header) as the producer saw it */
    uint32_t camera_id;       /* FNV-1a 32 of the camera name */
    uint32_t width;           /* pixels */
    uint32_t height;          /* pixels */
    float depth_scale;        /* metres per u16 depth unit (e.g. 0.001); 1.0 for f32 depth */
    uint8_t color_format;     /* FUSEPOSE_COLOR_* */
    uint8_t depth_format;     /* FUSEPOSE_DEPTH_* */
    uint8_t has_labels;       /* 1 when a label plane is present */
    uint8_t label_format;     /* FUSEPOSE_LABELS_* (ignored without labels; 3 needs has_labels = 1) */
    uint16_t instance_count;  /* label format 3: instance ids 1..instance_count; else 0 */
    uint16_t _reserved;       /* write 0 */
    uint64_t sequence;        /* producer frame counter, +1 per frame */
    uint64_t capture_time_ns; /* CLOCK_MONOTONIC ns */
    double fx;                /* pinhole intrinsics, pixels; pixel centres at integers */
    double fy;
    double cx;
    double cy;
    fp_plane_ref color;
    fp_plane_ref depth;
    fp_plane_ref labels;           /* class ids, or instance ids (format 3); empty without labels */
    fp_plane_ref instance_classes; /* format 3: instance_count + 1 uint16_t class ids; else empty */
    uint8_t _reserved_end[16];     /* write 0 */
} fp_frame_header;

/* One object's pose in the camera optical frame (88 bytes, no padding). */
typedef struct fp_object_pose {
    uint16_t class_id;          /* 1-based class id in the daemon's object set */
    uint16_t instance_id;       /* per frame: index among its instances, largest mask first; tracking mode: stable id */
    uint16_t refine_iterations; /* ICP or refiner iterations */
    uint16_t flags;             /* FUSEPOSE_POSE_* bits */
    float confidence;           /* 0..1 */
    uint32_t mask_pixels;       /* pixels of the instance mask */
    uint16_t bbox[4];           /* u_min, v_min, u_max, v_max, inclusive, pixels */
    double quaternion[4];       /* rotation object -> camera, unit, [x, y, z, w] */
    double translation_m[3];    /* translation object -> camera, metres */
    float fit_score;            /* 0..1, how well the pose explains depth and mask; NaN = not verified */
    float depth_residual_m;     /* median |depth residual| of the visible surface, metres; NaN = not verified */
} fp_object_pose;

/* The poses of one frame (2912 bytes). */
typedef struct fp_pose_message {
    uint16_t format_version;    /* FUSEPOSE_WIRE_VERSION */
    uint16_t object_count;      /* valid entries at the start of objects[] */
    uint32_t status;            /* FUSEPOSE_STATUS_* bits */
    uint32_t invalid_reason;    /* reason code when FUSEPOSE_STATUS_INVALID_FRAME, else 0 */
    uint32_t camera_id;
    uint64_t frame_sequence;    /* sequence of the frame these poses belong to */
    uint64_t capture_time_ns;   /* from the frame header, CLOCK_MONOTONIC ns */
    uint64_t received_time_ns;  /* when the daemon took the frame */
    uint64_t published_time_ns; /* when the daemon published this message */
    uint64_t stage_ns[FUSEPOSE_STAGE_COUNT]; /* per-stage durations, ns; 0 = not run */
    fp_object_pose objects[FUSEPOSE_MAX_OBJECTS];
} fp_pose_message;

/* A stats query. */
typedef struct fp_stats_request {
    uint16_t format_version;
    uint8_t _reserved[6];
} fp_stats_request;

/* Percentiles of one latency histogram, ns (all 0 when count is 0). */
typedef struct fp_latency_summary {
    uint64_t count;
    uint64_t p50_ns;
    uint64_t p90_ns;
    uint64_t p99_ns;
    uint64_t p999_ns;
    uint64_t max_ns;
} fp_latency_summary;

/* The daemon's counters and latency percentiles for one camera. */
typedef struct fp_stats_snapshot {
    uint16_t format_version;
    uint16_t _reserved;
    uint32_t camera_id;
    uint64_t uptime_ns;
    uint64_t window_ns;
    uint64_t deadline_ns;
    uint64_t frames_received;
    uint64_t frames_processed;
    uint64_t frames_skipped_stale;
    uint64_t frames_missed_sequence;
    uint64_t frames_invalid;
    uint64_t invalid_by_reason[FUSEPOSE_INVALID_REASON_COUNT];
    uint64_t deadline_misses;
    uint64_t estimator_failures;
    uint64_t poses_non_finite;
    uint64_t producer_restarts;
    fp_latency_summary since_start[FUSEPOSE_TIMELINE_COUNT];
    fp_latency_summary last_window[FUSEPOSE_TIMELINE_COUNT];
    uint64_t poses_failed_verification;
    uint64_t objects_shed;
    uint64_t frames_degraded;
} fp_stats_snapshot;

/* One camera's sight of a cell object (32 bytes). */
typedef struct fp_cell_view {
    uint32_t camera_id;         /* FNV-1a 32 of the camera name */
    uint16_t instance_id;       /* the pose's instance_id in that camera's message of frame_sequence */
    uint16_t flags;             /* that pose's FUSEPOSE_POSE_* bits */
    float confidence;           /* that pose's confidence */
    float offset_m;             /* distance of this view's translation from the fused one, metres */
    uint64_t frame_sequence;    /* the camera frame the pose came from */
    uint64_t capture_time_ns;   /* its capture time, CLOCK_MONOTONIC ns */
} fp_cell_view;

/* One object in the cell frame (216 bytes). */
typedef struct fp_cell_object {
    uint16_t class_id;          /* 1-based class id in the daemon's object set */
    uint16_t view_count;        /* cameras that saw it (views[] lists up to FUSEPOSE_MAX_CELL_VIEWS) */
    uint16_t flags;             /* FUSEPOSE_CELL_* bits */
    uint16_t reserved;
    float confidence;           /* the highest of the views' */
    float spread_m;             /* largest view offset from the fused translation, metres */
    double quaternion[4];       /* rotation object -> cell, unit, [x, y, z, w] */
    double translation_m[3];    /* translation object -> cell, metres */
    uint64_t newest_capture_time_ns;
    uint64_t oldest_capture_time_ns;
    fp_cell_view views[FUSEPOSE_MAX_CELL_VIEWS]; /* the view whose pose it carries first; unused zero */
} fp_cell_object;

/* The cell's objects after one posed camera frame (13856 bytes). */
typedef struct fp_cell_pose_message {
    uint16_t format_version;    /* FUSEPOSE_WIRE_VERSION */
    uint16_t object_count;      /* valid entries at the start of objects[] */
    uint16_t camera_count;      /* cameras whose latest poses were fresh enough to join */
    uint16_t truncated;         /* 1 when objects did not fit (least confident left out) */
    uint32_t trigger_camera_id; /* the camera whose frame triggered this message */
    uint32_t reserved;
    uint64_t sequence;          /* counts cell messages from 0 since the daemon started */
    uint64_t published_time_ns;
    fp_cell_object objects[FUSEPOSE_MAX_CELL_OBJECTS];
} fp_cell_pose_message;

#ifdef __cplusplus
}
#endif

#endif /* FUSEPOSE_H */
