/* libpheromone from C: attach to a running field, wait for a frame, read it zero-copy, deposit.
 *
 *   cc read_deposit.c $(pkg-config --cflags --libs pheromone) -o read_deposit
 *   pheromone field --name demo &
 *   ./read_deposit demo [LOOPS]
 *
 * Each of LOOPS rounds (default 1) attaches, waits for a frame, borrows it, reads the cell
 * under the grid's centre straight from shared memory and samples the value and gradient there,
 * releases the frame and detaches. The last round also deposits seed 000's uncertainty-aware
 * ellipse for a pose with its 3x3 covariance. */
#include <inttypes.h>
#include <stdio.h>
#include <stdlib.h>

#include "pheromone.h"

static int fail(const char *what, PheromoneStatus s) {
    fprintf(stderr, "read_deposit: %s: status %d: %s\n", what, (int)s, pheromone_last_error());
    return 1;
}

static int round_trip(const char *name, int deposit) {
    PheromoneAttachOptions options;
    PheromoneStatus s = pheromone_attach_options_init(&options);
    if (s != PHEROMONE_STATUS_OK) return fail("options", s);
    options.attach_timeout_ns = 5000000000ull; /* the field may still be starting */
    options.deposits = deposit;
    PheromoneField *field = NULL;
    s = pheromone_field_attach(name, &options, &field);
    if (s != PHEROMONE_STATUS_OK) return fail("attach", s);

    PheromoneWaitPolicy wait = {PHEROMONE_WAIT_EVENT, 0};
    s = pheromone_wait_frame(field, wait, 2000000000ull);
    if (s != PHEROMONE_STATUS_OK && s != PHEROMONE_STATUS_TIMEOUT) return fail("wait", s);

    PheromoneFrameView frame;
    s = pheromone_frame_borrow(field, &frame);
    if (s != PHEROMONE_STATUS_OK) return fail("borrow", s);
    /* The plane is the field's shared memory: no copy was made. */
    uint32_t cx = frame.width / 2, cy = frame.height / 2;
    float cell = frame.planes[0][(size_t)cy * frame.width + cx];
    float x = frame.origin_x_m + (cx + 0.5f) * frame.cell_size_m;
    float y = frame.origin_y_m + (cy + 0.5f) * frame.cell_size_m;
    float value = 0, gx = 0, gy = 0;
    s = pheromone_sample_value(field, 0, x, y, &value);
    if (s == PHEROMONE_STATUS_OK) s = pheromone_sample_gradient(field, 0, x, y, &gx, &gy);
    uint64_t sequence = frame.sequence;
    pheromone_frame_release(field); /* frame.planes must not be used from here on */
    if (s != PHEROMONE_STATUS_OK) return fail("sample", s);
    printf("frame %" PRIu64 ": cell (%u, %u) = %g; at (%g, %g) value %g gradient (%g, %g)\n",
           sequence, cx, cy, cell, x, y, value, gx, gy);

    if (deposit) {
        PheromonePoseEstimate pose = {x, y, 0.0, {0.01, 0.002, 0.0, 0.002, 0.02, 0.0, 0.0, 0.0, 0.05}};
        s = pheromone_deposit_pose(field, &pose, NULL); /* NULL: the depositor's defaults */
        if (s != PHEROMONE_STATUS_OK) return fail("deposit", s);
        printf("deposited at (%g, %g)\n", x, y);
    }
    s = pheromone_field_detach(field);
    if (s != PHEROMONE_STATUS_OK) return fail("detach", s);
    return 0;
}

int main(int argc, char **argv) {
    if (argc < 2) {
        fprintf(stderr, "usage: read_deposit FIELD [LOOPS]\n");
        return 2;
    }
    int loops = argc > 2 ? atoi(argv[2]) : 1;
    if (loops < 1) {
        fprintf(stderr, "read_deposit: LOOPS '%s' must be a whole number >= 1\n", argv[2]);
        return 2;
    }
    for (int i = 0; i < loops; i++)
        if (round_trip(argv[1], i == loops - 1)) return 1;
    return 0;
}
