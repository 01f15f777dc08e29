/*
 * pthread_cond_timedwait with a wrapped "wait for ever" deadline waits for ever.
 *
 * Fast DDS 2.14 as the ros-jazzy wheels ship it (libfastrtps.so.2.14) waits in
 * DomainParticipant::set_listener with a steady_clock deadline of time_point::max(),
 * which rmw_fastrtps' destroy_participant passes. Its compiled libstdc++ re-bases that
 * deadline onto the system clock: max - steady_now + system_now wraps to a time before
 * 1970 with a negative tv_nsec. glibc refuses such a deadline with EINVAL without
 * releasing the mutex, so the loop around the wait spins for ever, holding the mutex
 * that a discovery callback in flight needs in order to end: the process never stops.
 *
 * Preloaded (LD_PRELOAD), this file passes every valid deadline to glibc unchanged and
 * turns only the invalid one before 1970 into pthread_cond_wait, which is what the
 * caller asked for: wait until notified.
 */
#define _GNU_SOURCE
#include <dlfcn.h>
#include <pthread.h>
#include <time.h>

typedef int (*timedwait_fn)(pthread_cond_t *, pthread_mutex_t *, const struct timespec *);

static timedwait_fn glibc_timedwait;

__attribute__((constructor)) static void find_glibc_timedwait(void)
{
  glibc_timedwait = (timedwait_fn)dlsym(RTLD_NEXT, "pthread_cond_timedwait");
}

int pthread_cond_timedwait(pthread_cond_t *cond, pthread_mutex_t *mutex,
                           const struct timespec *deadline)
{
  if (deadline->tv_sec < 0 &&
      (deadline->tv_nsec < 0 || deadline->tv_nsec >= 1000000000L)) {
    return pthread_cond_wait(cond, mutex);
  }
  if (glibc_timedwait == NULL) {
    find_glibc_timedwait();     /* called before this library's constructor ran */
  }
  return glibc_timedwait(cond, mutex, deadline);
}
