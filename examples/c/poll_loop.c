/* A field and a timer in one poll(2) loop: the program's own event loop, not a blocking wait.
 *
 *   poll_loop FIELD FRAMES TIMER_TICKS
 *
 * Attaches (read-only) to FIELD, takes the descriptor of its frame-ready event
 * (pheromone_field_fd) and a timerfd that expires every 50 ms, and polls both until it has
 * taken FRAMES new frames and counted TIMER_TICKS timer expirations. When the field's descriptor
 * is readable, pheromone_wait_frame with a zero timeout takes the pending notifications and the
 * newest frame: PHEROMONE_STATUS_OK (a new frame: its sequence is printed) or
 * PHEROMONE_STATUS_TIMEOUT (a wake-up for a frame already taken: counted as spurious). Prints
 * "frame SEQ" and "timer N" lines, then "done frames F timer T wakeups W spurious S".
 *
 * Build: cc -std=c99 poll_loop.c $(pkg-config --cflags --libs pheromone)
 */
#define _POSIX_C_SOURCE 200809L

#include <errno.h>
#include <pheromone.h>
#include <poll.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/timerfd.h>
#include <unistd.h>

static int fail(const char *what, PheromoneStatus s) {
    fprintf(stderr, "%s: %s: %s\n", what, pheromone_status_str((int32_t)s), pheromone_last_error());
    return 1;
}

int main(int argc, char **argv) {
    PheromoneAttachOptions options;
    PheromoneField *field = NULL;
    PheromoneWaitPolicy event = {PHEROMONE_WAIT_EVENT, 0};
    PheromoneFrameView view;
    struct itimerspec period;
    struct pollfd fds[2];
    long frames_wanted, ticks_wanted, frames = 0, ticks = 0, wakeups = 0, spurious = 0;
    int field_fd = -1, timer_fd;
    PheromoneStatus s;

    if (argc != 4) {
        fprintf(stderr, "usage: poll_loop FIELD FRAMES TIMER_TICKS\n");
        return 2;
    }
    frames_wanted = atol(argv[2]);
    ticks_wanted = atol(argv[3]);
    pheromone_attach_options_init(&options);
    options.deposits = 0;
    options.attach_timeout_ns = 10000000000ull;
    s = pheromone_field_attach(argv[1], &options, &field);
    if (s != PHEROMONE_STATUS_OK) return fail("attach", s);
    s = pheromone_field_fd(field, &field_fd);
    if (s != PHEROMONE_STATUS_OK) return fail("field fd", s);

    timer_fd = timerfd_create(CLOCK_MONOTONIC, 0);
    if (timer_fd < 0) {
        perror("timerfd_create");
        return 1;
    }
    memset(&period, 0, sizeof period);
    period.it_interval.tv_nsec = 50000000; /* 50 ms */
    period.it_value.tv_nsec = 50000000;
    if (timerfd_settime(timer_fd, 0, &period, NULL) != 0) {
        perror("timerfd_settime");
        return 1;
    }

    fds[0].fd = field_fd;
    fds[0].events = POLLIN;
    fds[1].fd = timer_fd;
    fds[1].events = POLLIN;
    while (frames < frames_wanted || ticks < ticks_wanted) {
        int n = poll(fds, 2, 5000);
        if (n < 0 && errno == EINTR) continue;
        if (n < 0) {
            perror("poll");
            return 1;
        }
        if (n == 0) {
            fprintf(stderr, "neither a frame nor the timer within 5 s\n");
            return 1;
        }
        wakeups++;
        if (fds[1].revents & POLLIN) {
            uint64_t expirations = 0;
            if (read(timer_fd, &expirations, sizeof expirations) != (ssize_t)sizeof expirations) {
                perror("read timerfd");
                return 1;
            }
            ticks += (long)expirations;
            printf("timer %ld\n", ticks);
        }
        if (fds[0].revents & POLLIN) {
            s = pheromone_wait_frame(field, event, 0);
            if (s == PHEROMONE_STATUS_TIMEOUT) {
                spurious++;
                continue;
            }
            if (s != PHEROMONE_STATUS_OK) return fail("wait", s);
            s = pheromone_frame_borrow(field, &view);
            if (s != PHEROMONE_STATUS_OK) return fail("borrow", s);
            printf("frame %llu\n", (unsigned long long)view.sequence);
            pheromone_frame_release(field);
            frames++;
        }
    }
    printf("done frames %ld timer %ld wakeups %ld spurious %ld\n", frames, ticks, wakeups,
           spurious);
    close(timer_fd);
    s = pheromone_field_detach(field);
    if (s != PHEROMONE_STATUS_OK) return fail("detach", s);
    return 0;
}
