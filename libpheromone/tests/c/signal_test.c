/* A C program keeps its own SIGTERM handling while it waits on a field (issue 47); run by
 * libpheromone/tests/c_abi.sh, which sends the SIGTERMs from outside:
 *
 *   signal_test FIELD WAITS
 *
 * Installs its own SIGTERM handler (sigaction, no SA_RESTART), records the disposition of every
 * signal, attaches and prints "ready". Then WAITS times: a blocking event wait for a frame (up to
 * 60 s; the test's field ticks every 100 s, so only a signal ends it early) must return
 * PHEROMONE_STATUS_INTERRUPTED with the handler run since the wait began: prints
 * "interrupted I". Then a confirmed deposit waiting for its receipt (the field answers at its next
 * tick) must return PHEROMONE_STATUS_INTERRUPTED too: "interrupted deposit". Then it reads a line
 * from stdin (the driver sends no more signals), checks that no signal's disposition changed, and
 * prints "seen K": the SIGTERMs its handler ran for, which the driver compares with the number it
 * sent. Exit status 0 when every check held, 1 otherwise (the reason on stderr).
 */
#define _POSIX_C_SOURCE 200809L

#include <pheromone.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static volatile sig_atomic_t seen = 0;

static void on_term(int sig) {
    (void)sig;
    seen = seen + 1;
}

#define MAX_SIG 65
static struct sigaction before[MAX_SIG];
static int known[MAX_SIG];

static void record_dispositions(void) {
    int s;
    for (s = 1; s < MAX_SIG; s++) {
        known[s] = sigaction(s, NULL, &before[s]) == 0;
    }
}

/* 0 when every signal's handler and flags are what they were when recorded. */
static int dispositions_changed(void) {
    int s, changed = 0;
    for (s = 1; s < MAX_SIG; s++) {
        struct sigaction now;
        if (!known[s] || sigaction(s, NULL, &now) != 0) {
            continue;
        }
        if (now.sa_handler != before[s].sa_handler || now.sa_flags != before[s].sa_flags) {
            fprintf(stderr, "signal %d: its disposition changed during the library's calls\n", s);
            changed = 1;
        }
    }
    return changed;
}

static int failed(const char *what, PheromoneStatus got, PheromoneStatus expected) {
    fprintf(stderr, "%s: status %d (%s), expected %d (%s): %s\n", what, (int)got,
            pheromone_status_str((int32_t)got), (int)expected,
            pheromone_status_str((int32_t)expected), pheromone_last_error());
    return 1;
}

int main(int argc, char **argv) {
    PheromoneField *field = NULL;
    PheromoneAttachOptions options;
    PheromoneWaitPolicy event = {PHEROMONE_WAIT_EVENT, 0};
    PheromoneDeposit d;
    PheromoneReceipt receipt;
    struct sigaction sa;
    PheromoneStatus s;
    char line[64];
    int waits, i;

    if (argc != 3) {
        fprintf(stderr, "usage: signal_test FIELD WAITS\n");
        return 2;
    }
    waits = atoi(argv[2]);
    memset(&sa, 0, sizeof sa);
    sa.sa_handler = on_term;
    sigemptyset(&sa.sa_mask);
    sa.sa_flags = 0;
    if (sigaction(SIGTERM, &sa, NULL) != 0) {
        perror("sigaction");
        return 1;
    }
    record_dispositions();

    s = pheromone_attach_options_init(&options);
    if (s != PHEROMONE_STATUS_OK) {
        return failed("options", s, PHEROMONE_STATUS_OK);
    }
    options.attach_timeout_ns = 10000000000ull; /* the field may be starting */
    s = pheromone_field_attach(argv[1], &options, &field);
    if (s != PHEROMONE_STATUS_OK) {
        return failed("attach", s, PHEROMONE_STATUS_OK);
    }
    /* The field's current frame (its history, handed over at the field's next look at its
     * readers): held before the waits below, each of which is for a newer one. */
    {
        PheromoneFrameView view;
        s = pheromone_frame_borrow(field, &view);
        if (s == PHEROMONE_STATUS_NO_FRAME) {
            s = pheromone_wait_frame(field, event, 10000000000ull);
            if (s != PHEROMONE_STATUS_OK) {
                return failed("the field's current frame", s, PHEROMONE_STATUS_OK);
            }
        } else if (s != PHEROMONE_STATUS_OK) {
            return failed("borrow", s, PHEROMONE_STATUS_OK);
        }
        pheromone_frame_release(field);
    }
    printf("ready\n");
    fflush(stdout);

    for (i = 1; i <= waits; i++) {
        sig_atomic_t at_start = seen;
        s = pheromone_wait_frame(field, event, 60000000000ull);
        if (s != PHEROMONE_STATUS_INTERRUPTED) {
            return failed("wait", s, PHEROMONE_STATUS_INTERRUPTED);
        }
        if (seen == at_start) {
            fprintf(stderr, "wait %d: interrupted, but the program's handler did not run\n", i);
            return 1;
        }
        printf("interrupted %d\n", i);
        fflush(stdout);
    }

    memset(&d, 0, sizeof d);
    d.kernel = PHEROMONE_KERNEL_ELLIPSE;
    d.amount = 0.01f;
    d.cov_xx = 0.04f;
    d.cov_yy = 0.04f;
    d.range_m = 0.5f;
    d.gamma_max = 100.0f;
    {
        sig_atomic_t at_start = seen;
        s = pheromone_deposit_confirmed(field, &d, 60000000000ull, &receipt);
        if (s != PHEROMONE_STATUS_INTERRUPTED) {
            return failed("confirmed deposit", s, PHEROMONE_STATUS_INTERRUPTED);
        }
        if (seen == at_start) {
            fprintf(stderr, "confirmed deposit: interrupted, but the handler did not run\n");
            return 1;
        }
    }
    printf("interrupted deposit\n");
    fflush(stdout);

    /* The driver's "end": no SIGTERM comes after it. */
    if (fgets(line, sizeof line, stdin) == NULL) {
        fprintf(stderr, "stdin closed before the driver's end line\n");
        return 1;
    }
    if (dispositions_changed()) {
        return 1;
    }
    s = pheromone_field_detach(field);
    if (s != PHEROMONE_STATUS_OK) {
        return failed("detach", s, PHEROMONE_STATUS_OK);
    }
    printf("seen %d\n", (int)seen);
    return 0;
}
