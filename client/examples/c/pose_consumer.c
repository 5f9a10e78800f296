/*
 * pose_consumer.c - parse fusepose pose messages in C (C99).
 *
 * A pose message is one fixed-size fp_pose_message (client/include/fusepose.h).
 * A C or C++ program subscribed to "fusepose/camera/<name>/poses" with
 * iceoryx2's C bindings receives exactly these bytes as the sample payload
 * (see README.md, "Consumers in C and C++", for building those bindings);
 * fp_parse_pose_message() checks them the way the Rust client does.
 *
 * This example reads raw messages from a file (or stdin), e.g. one written by
 * a logger, and prints every object's pose:
 *
 *   cc -std=c99 -Wall -I client/include client/examples/c/pose_consumer.c -o pose_consumer
 *   ./pose_consumer poses.bin
 */
#include <stdint.h>
#include <stdio.h>
#include <string.h>

#include "fusepose.h"

/* Why a buffer is not a usable pose message. */
typedef enum fp_parse_result {
    FP_PARSE_OK = 0,
    FP_PARSE_SHORT = 1,       /* fewer bytes than sizeof(fp_pose_message) */
    FP_PARSE_VERSION = 2,     /* another wire version: rebuild against its header */
    FP_PARSE_OBJECT_COUNT = 3 /* object_count > FUSEPOSE_MAX_OBJECTS */
} fp_parse_result;

/* Copies `len` bytes into `out` (no alignment needed) and checks them. */
static fp_parse_result fp_parse_pose_message(const uint8_t *bytes, size_t len, fp_pose_message *out) {
    if (len < sizeof(fp_pose_message)) {
        return FP_PARSE_SHORT;
    }
    memcpy(out, bytes, sizeof(fp_pose_message));
    if (out->format_version != FUSEPOSE_WIRE_VERSION) {
        return FP_PARSE_VERSION;
    }
    if (out->object_count > FUSEPOSE_MAX_OBJECTS) {
        return FP_PARSE_OBJECT_COUNT;
    }
    return FP_PARSE_OK;
}

static void print_message(const fp_pose_message *m) {
    double latency_ms = (double)(m->published_time_ns - m->capture_time_ns) / 1e6;
    printf("frame %llu status 0x%x objects %u latency %.3f ms\n", (unsigned long long)m->frame_sequence,
           (unsigned)m->status, (unsigned)m->object_count, latency_ms);
    if (m->status & FUSEPOSE_STATUS_INVALID_FRAME) {
        printf("  invalid frame, reason code %u\n", (unsigned)m->invalid_reason);
    }
    for (unsigned i = 0; i < m->object_count; ++i) {
        const fp_object_pose *o = &m->objects[i];
        printf("  class %u instance %u xyz_mm %.1f %.1f %.1f q_xyzw %.4f %.4f %.4f %.4f conf %.2f flags 0x%x",
               (unsigned)o->class_id, (unsigned)o->instance_id, o->translation_m[0] * 1e3, o->translation_m[1] * 1e3,
               o->translation_m[2] * 1e3, o->quaternion[0], o->quaternion[1], o->quaternion[2], o->quaternion[3],
               (double)o->confidence, (unsigned)o->flags);
        /* fit_score and depth_residual_m are NaN unless the pose was verified. */
        if (o->flags & FUSEPOSE_POSE_VERIFIED) {
            printf(" fit %.2f residual_mm %.1f", (double)o->fit_score, (double)o->depth_residual_m * 1e3);
        }
        printf("\n");
    }
}

int main(int argc, char **argv) {
    FILE *in = stdin;
    if (argc > 1 && (in = fopen(argv[1], "rb")) == NULL) {
        perror(argv[1]);
        return 2;
    }
    static uint8_t buffer[sizeof(fp_pose_message)];
    fp_pose_message msg;
    int messages = 0;
    size_t got;
    while ((got = fread(buffer, 1, sizeof buffer, in)) > 0) {
        fp_parse_result r = fp_parse_pose_message(buffer, got, &msg);
        if (r != FP_PARSE_OK) {
            fprintf(stderr, "message %d: not a fusepose v%d pose message (error %d)\n", messages,
                    FUSEPOSE_WIRE_VERSION, (int)r);
            return 1;
        }
        print_message(&msg);
        ++messages;
    }
    if (in != stdin) {
        fclose(in);
    }
    printf("%d messages\n", messages);
    return 0;
}
