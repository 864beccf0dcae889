/* The C ABI against a live `pheromone field` (run by libpheromone/tests/c_abi.sh):
 *
 *   abi_test errors MISSING_FIELD LIVE_FIELD   statuses and messages of the error cases
 *   abi_test sample FIELD X,Y ...              prints "x y value" per point, from one frame
 *   abi_test frames FIELD X Y                  planes inside the shared-memory mapping, frame
 *                                              bytes changing, a pose deposit from C
 *   abi_test confirm FIELD X Y                 confirmed deposits: applied in frame N (and
 *                                              seen there), refused with the field's reason,
 *                                              no receipt within a zero timeout
 *   abi_test hold FIELD                        attaches (generation 1, alive), prints "holding";
 *                                              on the stdin line "dead" waits until the field is
 *                                              no longer alive, on "restarted" until a frame of
 *                                              generation 2 comes (alive again); detaches at the
 *                                              end of stdin
 *   abi_test dead FIELD                        the field's process died while another process
 *                                              holds its services: PHEROMONE_STATUS_FIELD_DEAD
 *
 * Exits 0 when every check holds, 1 (with the reason on stderr) otherwise. */
#include <inttypes.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "pheromone.h"

static int failures = 0;

#define CHECK(cond, ...)                                          \
    do {                                                          \
        if (!(cond)) {                                            \
            fprintf(stderr, "abi_test:%d: check failed: %s: ", __LINE__, #cond); \
            fprintf(stderr, __VA_ARGS__);                         \
            fprintf(stderr, "\n");                                \
            failures++;                                           \
        }                                                         \
    } while (0)

#define MUST(call)                                                                    \
    do {                                                                              \
        PheromoneStatus s_ = (call);                                                  \
        if (s_ != PHEROMONE_STATUS_OK) {                                              \
            fprintf(stderr, "abi_test:%d: %s returned %d: %s\n", __LINE__, #call, (int)s_, \
                    pheromone_last_error());                                          \
            exit(1);                                                                  \
        }                                                                             \
    } while (0)

static const uint64_t SECOND_NS = 1000000000ull;

static PheromoneField *attach(const char *name) {
    PheromoneAttachOptions o;
    MUST(pheromone_attach_options_init(&o));
    o.attach_timeout_ns = 10 * SECOND_NS;
    o.robot_id = 42;
    PheromoneField *f = NULL;
    MUST(pheromone_field_attach(name, &o, &f));
    return f;
}

/* Whether `last_error` mentions `needle`. */
static int says(const char *needle) { return strstr(pheromone_last_error(), needle) != NULL; }

static int run_errors(const char *missing, const char *live) {
    PheromoneField *f = (PheromoneField *)0x1;
    PheromoneStatus s = pheromone_field_attach(missing, NULL, &f);
    CHECK(s == PHEROMONE_STATUS_NO_FIELD, "missing field: status %d", (int)s);
    CHECK(f == NULL, "a failed attach leaves *out NULL");
    CHECK(says(missing), "the message names the field: %s", pheromone_last_error());
    CHECK(says("default domain"), "the message names the domain: %s", pheromone_last_error());
    {
        PheromoneAttachOptions od;
        MUST(pheromone_attach_options_init(&od));
        od.iox_domain = "capi-other-domain";
        s = pheromone_field_attach(live, &od, &f);
        CHECK(s == PHEROMONE_STATUS_NO_FIELD && says("domain 'capi-other-domain'"),
              "a live field in another domain: %d %s", (int)s, pheromone_last_error());
    }
    CHECK(strcmp(pheromone_status_str(PHEROMONE_STATUS_NO_FIELD),
                 "no field of that name is running") == 0,
          "status_str(NO_FIELD): %s", pheromone_status_str(PHEROMONE_STATUS_NO_FIELD));
    CHECK(strcmp(pheromone_status_str(-3), "unknown status") == 0, "status_str(-3)");
    s = pheromone_set_log_level(99);
    CHECK(s == PHEROMONE_STATUS_BAD_ARGUMENT && says("log level = 99"), "log level 99: %d %s",
          (int)s, pheromone_last_error());

    s = pheromone_field_attach(NULL, NULL, &f);
    CHECK(s == PHEROMONE_STATUS_BAD_ARGUMENT && says("name is NULL"), "NULL name: %d %s", (int)s,
          pheromone_last_error());
    s = pheromone_field_attach("bad/name", NULL, &f);
    CHECK(s == PHEROMONE_STATUS_BAD_ARGUMENT && says("bad/name"), "bad name: %d %s", (int)s,
          pheromone_last_error());

    PheromoneAttachOptions o;
    MUST(pheromone_attach_options_init(&o));
    o.layout_version = PHEROMONE_LAYOUT_VERSION + 1;
    s = pheromone_field_attach(live, &o, &f);
    CHECK(s == PHEROMONE_STATUS_LAYOUT && says("layout_version"), "old header: %d %s", (int)s,
          pheromone_last_error());

    PheromoneField *h = attach(live);
    PheromoneFrameView v;
    PheromoneWaitPolicy bad_policy = {7, 0};
    s = pheromone_wait_frame(h, bad_policy, SECOND_NS);
    CHECK(s == PHEROMONE_STATUS_BAD_ARGUMENT && says("kind = 7"), "bad policy: %d %s", (int)s,
          pheromone_last_error());
    float out = 0;
    s = pheromone_sample_value(h, 0, 1.0f, 1.0f, &out);
    CHECK(s == PHEROMONE_STATUS_NO_FRAME, "sampling before a borrow: %d", (int)s);
    PheromoneWaitPolicy event = {PHEROMONE_WAIT_EVENT, 0};
    s = pheromone_wait_frame(h, event, 5 * SECOND_NS);
    CHECK(s == PHEROMONE_STATUS_OK, "a frame within 5 s: %d %s", (int)s, pheromone_last_error());
    MUST(pheromone_frame_borrow(h, &v));
    s = pheromone_sample_value(h, v.channels, 1.0f, 1.0f, &out);
    CHECK(s == PHEROMONE_STATUS_BAD_ARGUMENT && says("channel = "), "bad channel: %d %s", (int)s,
          pheromone_last_error());
    s = pheromone_sample_value(h, 0, NAN, 1.0f, &out);
    CHECK(s == PHEROMONE_STATUS_BAD_ARGUMENT && says("x_m = NaN"), "NaN x: %d %s", (int)s,
          pheromone_last_error());
    s = pheromone_sample_value(h, 0, 1.0f, 1.0f, NULL);
    CHECK(s == PHEROMONE_STATUS_BAD_ARGUMENT && says("out is NULL"), "NULL out: %d", (int)s);
    float sectors[3];
    PheromonePose pose = {1.0f, 1.0f, 0.0f};
    s = pheromone_sample_sectors(h, 0, pose, 1.0f, 2, sectors, 3);
    CHECK(s == PHEROMONE_STATUS_BAD_ARGUMENT && says("out_len"), "short sector buffer: %d %s",
          (int)s, pheromone_last_error());
    s = pheromone_wait_frame(h, event, SECOND_NS);
    CHECK(s == PHEROMONE_STATUS_BORROWED, "waiting while borrowed: %d", (int)s);
    s = pheromone_field_detach(h);
    CHECK(s == PHEROMONE_STATUS_BORROWED, "detaching while borrowed: %d", (int)s);
    MUST(pheromone_frame_release(h));

    PheromoneDeposit d = {0};
    d.kernel = PHEROMONE_KERNEL_ELLIPSE;
    d.x_m = 1.0f;
    d.y_m = 1.0f;
    d.amount = NAN;
    s = pheromone_deposit(h, &d);
    CHECK(s == PHEROMONE_STATUS_BAD_ARGUMENT && says("amount = NaN"), "NaN deposit: %d %s",
          (int)s, pheromone_last_error());
    d.amount = 0.1f;
    d.kernel = 9;
    s = pheromone_deposit(h, &d);
    CHECK(s == PHEROMONE_STATUS_BAD_ARGUMENT && says("kernel = 9"), "bad kernel: %d %s", (int)s,
          pheromone_last_error());
    /* Not positive semi-definite: |cov_xy| > sqrt(cov_xx * cov_yy). Refused before sending,
     * unconfirmed as well as confirmed. */
    d.kernel = PHEROMONE_KERNEL_ELLIPSE;
    d.cov_xx = 0.01f;
    d.cov_xy = 0.05f;
    d.cov_yy = 0.01f;
    d.range_m = 1.0f;
    d.gamma_max = 100.0f;
    s = pheromone_deposit(h, &d);
    CHECK(s == PHEROMONE_STATUS_BAD_ARGUMENT && says("not positive semi-definite"),
          "non-PSD deposit: %d %s", (int)s, pheromone_last_error());
    s = pheromone_deposit_confirmed(h, &d, SECOND_NS, NULL);
    CHECK(s == PHEROMONE_STATUS_BAD_ARGUMENT && says("cov_xy"), "non-PSD confirmed: %d %s",
          (int)s, pheromone_last_error());

    PheromonePoseEstimate p = {0};
    p.cov[0] = 0.01;
    p.cov[1] = 0.5; /* not symmetric: cov[1][0] stays 0 */
    p.cov[4] = 0.01;
    s = pheromone_deposit_pose(h, &p, NULL);
    CHECK(s == PHEROMONE_STATUS_BAD_ARGUMENT && says("not_symmetric"), "asymmetric cov: %d %s",
          (int)s, pheromone_last_error());
    MUST(pheromone_field_detach(h));
    CHECK(pheromone_field_detach(NULL) == PHEROMONE_STATUS_OK, "detach(NULL) is a no-op");
    if (failures == 0) printf("errors: ok\n");
    return failures ? 1 : 0;
}

/* Waits until the frame held has applied at least one deposit, then prints the points. */
static int run_sample(const char *name, int npoints, char **points) {
    PheromoneField *h = attach(name);
    PheromoneWaitPolicy spin = {PHEROMONE_WAIT_SPIN, 200000};
    PheromoneFrameView v;
    for (int tries = 0;; tries++) {
        PheromoneStatus s = pheromone_wait_frame(h, spin, 5 * SECOND_NS);
        if (s != PHEROMONE_STATUS_OK && s != PHEROMONE_STATUS_TIMEOUT) MUST(s);
        MUST(pheromone_frame_borrow(h, &v));
        if (v.deposits_applied > 0) break;
        MUST(pheromone_frame_release(h));
        if (tries > 500) {
            fprintf(stderr, "abi_test: no deposit applied in field %s\n", name);
            return 1;
        }
    }
    printf("frame %" PRIu64 "\n", v.sequence);
    for (int i = 0; i < npoints; i++) {
        float x, y, value, gx, gy;
        if (sscanf(points[i], "%f,%f", &x, &y) != 2) {
            fprintf(stderr, "abi_test: point '%s' is not X,Y\n", points[i]);
            return 1;
        }
        MUST(pheromone_sample_value(h, 0, x, y, &value));
        MUST(pheromone_sample_gradient(h, 0, x, y, &gx, &gy));
        printf("%.9g %.9g %.9g\n", x, y, value);
    }
    MUST(pheromone_frame_release(h));
    MUST(pheromone_field_detach(h));
    return 0;
}

/* The [start, end) of the /proc/self/maps entry holding `p`, with its path in `path`. */
static int mapping_of(const void *p, char *path, size_t path_len) {
    FILE *maps = fopen("/proc/self/maps", "r");
    if (!maps) return 0;
    char line[1024];
    int found = 0;
    while (fgets(line, sizeof line, maps)) {
        uintptr_t lo, hi;
        int consumed = 0;
        if (sscanf(line, "%" SCNxPTR "-%" SCNxPTR " %*s %*s %*s %*s %n", &lo, &hi, &consumed) < 2)
            continue;
        if ((uintptr_t)p >= lo && (uintptr_t)p < hi) {
            snprintf(path, path_len, "%s", line + consumed);
            path[strcspn(path, "\n")] = 0;
            found = 1;
            break;
        }
    }
    fclose(maps);
    return found;
}

static uint64_t checksum(const float *cells, size_t n) {
    uint64_t h = 1469598103934665603ull;
    const unsigned char *b = (const unsigned char *)cells;
    for (size_t i = 0; i < n * sizeof(float); i++) h = (h ^ b[i]) * 1099511628211ull;
    return h;
}

/* Frames: every plane lies in an iceoryx2 shared-memory mapping; after a C deposit at (x, y)
 * the bytes of later frames differ from the first, and the value there rises. */
static int run_frames(const char *name, float x, float y) {
    PheromoneField *h = attach(name);
    PheromoneWaitPolicy event = {PHEROMONE_WAIT_EVENT, 0};
    PheromoneFrameView v;
    PheromoneStatus s0 = pheromone_wait_frame(h, event, 5 * SECOND_NS);
    if (s0 != PHEROMONE_STATUS_TIMEOUT) MUST(s0);
    MUST(pheromone_frame_borrow(h, &v));
    char path[512];
    CHECK(mapping_of(v.planes[0], path, sizeof path), "plane %p is in no mapping", (void *)v.planes[0]);
    CHECK(strstr(path, "/dev/shm/") && strstr(path, "iox2"), "plane in '%s', not shared memory",
          path);
    uint64_t first = checksum(v.planes[0], v.plane_len);
    uint64_t first_seq = v.sequence;
    float before = 0;
    MUST(pheromone_sample_value(h, 0, x, y, &before));
    MUST(pheromone_frame_release(h));

    PheromonePoseEstimate pose = {0};
    pose.x_m = x;
    pose.y_m = y;
    pose.theta_rad = 0.7;
    const double cov[9] = {0.04, 0.01, 0.002, 0.01, 0.09, 0.003, 0.002, 0.003, 0.2};
    memcpy(pose.cov, cov, sizeof cov);
    MUST(pheromone_deposit_pose(h, &pose, NULL));

    int changed = 0, frames = 0;
    float after = before;
    for (int i = 0; i < 1000 && !(changed && after > before); i++) {
        PheromoneStatus s = pheromone_wait_frame(h, event, 5 * SECOND_NS);
        if (s == PHEROMONE_STATUS_TIMEOUT) break;
        MUST(s);
        MUST(pheromone_frame_borrow(h, &v));
        frames++;
        CHECK(mapping_of(v.planes[0], path, sizeof path) && strstr(path, "/dev/shm/"),
              "frame %" PRIu64 ": plane outside shared memory (%s)", v.sequence, path);
        CHECK(v.sequence > first_seq, "sequence %" PRIu64 " after %" PRIu64, v.sequence, first_seq);
        changed |= checksum(v.planes[0], v.plane_len) != first;
        MUST(pheromone_sample_value(h, 0, x, y, &after));
        MUST(pheromone_frame_release(h));
    }
    CHECK(changed, "the frame bytes never changed over %d frames", frames);
    CHECK(after > before, "the value at the C deposit stayed %g (before %g)", after, before);
    MUST(pheromone_field_detach(h));
    if (failures == 0)
        printf("frames: ok (%d frames, value %.9g -> %.9g, planes in %s)\n", frames, before, after,
               path);
    return failures ? 1 : 0;
}

/* Confirmed deposits: one at (x, y) is applied in the frame its receipt names, and that frame
 * shows it; one far outside the grid is refused with reason 5 (outside_grid) and leaves the
 * counter of applied deposits alone; with a zero timeout there is no receipt (TIMEOUT) and the
 * receipt is left untouched. */
static int run_confirm(const char *name, float x, float y) {
    PheromoneField *h = attach(name);
    const PheromoneWaitPolicy event = {PHEROMONE_WAIT_EVENT, 0};
    PheromoneDeposit d = {0};
    d.kernel = PHEROMONE_KERNEL_ELLIPSE;
    d.x_m = x;
    d.y_m = y;
    d.amount = 0.05f;
    d.cov_xx = 0.04f;
    d.cov_yy = 0.04f;
    d.range_m = 1.0f;
    d.gamma_max = 100.0f;
    PheromoneReceipt r = {0, 99, 99};
    MUST(pheromone_deposit_confirmed(h, &d, 10 * SECOND_NS, &r));
    CHECK(r.status == PHEROMONE_RECEIPT_APPLIED && r.sequence > 0 && r.reason == 0,
          "receipt %u seq %" PRIu64 " reason %u", r.status, r.sequence, r.reason);
    /* The frame named by the receipt (or a newer one) holds the deposit. */
    PheromoneFrameView v;
    for (int i = 0; i < 100; i++) {
        pheromone_wait_frame(h, event, SECOND_NS);
        MUST(pheromone_frame_borrow(h, &v));
        uint64_t seq = v.sequence;
        MUST(pheromone_frame_release(h));
        if (seq >= r.sequence) break;
    }
    MUST(pheromone_frame_borrow(h, &v));
    CHECK(v.sequence >= r.sequence, "frame %" PRIu64 " < receipt's %" PRIu64, v.sequence,
          r.sequence);
    float value = 0.0f;
    MUST(pheromone_sample_value(h, 0, x, y, &value));
    CHECK(value > 0.0f, "the value at the applied deposit is %g", value);
    uint64_t applied = v.deposits_applied;
    MUST(pheromone_frame_release(h));

    d.x_m = 1000.0f;
    PheromoneReceipt refused = {0, 99, 99};
    PheromoneStatus s = pheromone_deposit_confirmed(h, &d, 10 * SECOND_NS, &refused);
    CHECK(s == PHEROMONE_STATUS_REJECTED && says("outside_grid"), "outside: %d %s", (int)s,
          pheromone_last_error());
    CHECK(refused.status == PHEROMONE_RECEIPT_REJECTED && refused.reason == 5 &&
              refused.sequence >= r.sequence,
          "refused receipt %u reason %u seq %" PRIu64, refused.status, refused.reason,
          refused.sequence);
    CHECK(pheromone_deposit_confirmed(h, &d, 10 * SECOND_NS, NULL) == PHEROMONE_STATUS_REJECTED,
          "a NULL receipt is allowed");
    pheromone_wait_frame(h, event, SECOND_NS);
    MUST(pheromone_frame_borrow(h, &v));
    CHECK(v.deposits_applied == applied, "a refused deposit was applied: %" PRIu64 " -> %" PRIu64,
          applied, v.deposits_applied);
    MUST(pheromone_frame_release(h));

    d.x_m = x;
    d.amount = NAN;
    s = pheromone_deposit_confirmed(h, &d, SECOND_NS, &r);
    CHECK(s == PHEROMONE_STATUS_BAD_ARGUMENT && says("amount = NaN"), "NaN: %d %s", (int)s,
          pheromone_last_error());
    d.amount = 0.01f;
    PheromoneReceipt untouched = {7, 77, 777};
    s = pheromone_deposit_confirmed(h, &d, 0, &untouched);
    CHECK(s == PHEROMONE_STATUS_TIMEOUT, "zero timeout: %d %s", (int)s, pheromone_last_error());
    CHECK(untouched.sequence == 7 && untouched.status == 77 && untouched.reason == 777,
          "the receipt was written without an answer");
    MUST(pheromone_field_detach(h));
    if (failures == 0) printf("confirm: applied in frame %" PRIu64 ", refused (reason 5): ok\n",
                              r.sequence);
    return failures ? 1 : 0;
}

/* Waits (in 50 ms frame waits, at most 200 of them) until `*l` says `alive` and at least
 * `generation`; returns whether it did. */
static int await_liveness(PheromoneField *f, PheromoneLiveness *l, uint32_t alive,
                          uint64_t generation) {
    PheromoneWaitPolicy event = {PHEROMONE_WAIT_EVENT, 0};
    for (int i = 0; i < 200; i++) {
        PheromoneStatus s = pheromone_wait_frame(f, event, SECOND_NS / 20);
        if (s != PHEROMONE_STATUS_OK && s != PHEROMONE_STATUS_TIMEOUT) return 0;
        if (pheromone_field_liveness(f, l) != PHEROMONE_STATUS_OK) return 0;
        if (l->alive == alive && l->generation >= generation) return 1;
    }
    return 0;
}

static int run_hold(const char *name) {
    PheromoneAttachOptions o;
    PheromoneField *f = NULL;
    PheromoneLiveness l;
    char line[64];
    MUST(pheromone_attach_options_init(&o));
    o.attach_timeout_ns = 10 * SECOND_NS;
    o.deposits = 0;
    MUST(pheromone_field_attach(name, &o, &f));
    CHECK(await_liveness(f, &l, 1, 1) && l.generation == 1,
          "a live field's first frames: alive %u generation %" PRIu64, l.alive, l.generation);
    printf("holding\n");
    fflush(stdout);
    while (fgets(line, sizeof line, stdin) != NULL) {
        if (strcmp(line, "dead\n") == 0) {
            CHECK(await_liveness(f, &l, 0, 1) && l.generation == 1,
                  "the killed field: alive %u generation %" PRIu64, l.alive, l.generation);
            printf("dead: alive %u generation %" PRIu64 "\n", l.alive, l.generation);
        } else if (strcmp(line, "restarted\n") == 0) {
            CHECK(await_liveness(f, &l, 1, 2) && l.generation == 2,
                  "the restarted field: alive %u generation %" PRIu64, l.alive, l.generation);
            printf("restarted: alive %u generation %" PRIu64 "\n", l.alive, l.generation);
        }
        fflush(stdout);
    }
    MUST(pheromone_field_detach(f));
    return failures ? 1 : 0;
}

static int run_dead(const char *name) {
    PheromoneAttachOptions o;
    PheromoneField *f = (PheromoneField *)0x1;
    MUST(pheromone_attach_options_init(&o));
    o.attach_timeout_ns = SECOND_NS / 2;
    PheromoneStatus s = pheromone_field_attach(name, &o, &f);
    CHECK(s == PHEROMONE_STATUS_FIELD_DEAD, "attach to a dead field: %d %s", (int)s,
          pheromone_last_error());
    CHECK(f == NULL, "a failed attach leaves *out NULL");
    CHECK(says(name) && says("died"), "the message names the field: %s", pheromone_last_error());
    if (failures == 0) printf("dead: %s\n", pheromone_last_error());
    return failures ? 1 : 0;
}

int main(int argc, char **argv) {
    /* iceoryx2's log level is the program's to set (the library never changes it): quiet. */
    MUST(pheromone_set_log_level(PHEROMONE_LOG_FATAL));
    if (argc >= 4 && strcmp(argv[1], "errors") == 0) return run_errors(argv[2], argv[3]);
    if (argc >= 3 && strcmp(argv[1], "sample") == 0) return run_sample(argv[2], argc - 3, argv + 3);
    if (argc == 5 && strcmp(argv[1], "frames") == 0)
        return run_frames(argv[2], strtof(argv[3], NULL), strtof(argv[4], NULL));
    if (argc == 5 && strcmp(argv[1], "confirm") == 0)
        return run_confirm(argv[2], strtof(argv[3], NULL), strtof(argv[4], NULL));
    if (argc == 3 && strcmp(argv[1], "hold") == 0) return run_hold(argv[2]);
    if (argc == 3 && strcmp(argv[1], "dead") == 0) return run_dead(argv[2]);
    fprintf(stderr, "usage: abi_test errors MISSING LIVE | sample FIELD X,Y... | frames FIELD X Y | confirm FIELD X Y | hold FIELD | dead FIELD\n");
    return 2;
}
