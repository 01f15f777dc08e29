/*
 * Forces the race of rmw_fastrtps' destroy_participant: DomainParticipant::set_listener(nullptr)
 * waits until slow_discovery.c holds a discovery callback in flight, then goes on.
 * Flag files in $RACE_DIR: "slow" (asked for), "held" (a callback is held).
 */
#define _GNU_SOURCE
#include <dlfcn.h>
#include <limits.h>
#include <stdio.h>
#include <stdlib.h>
#include <unistd.h>

#define SET_LISTENER \
  "_ZN8eprosima7fastdds3dds17DomainParticipant12set_listenerEPNS1_25DomainParticipantListenerE"

typedef int (*set_listener_fn)(void *, void *);

static void flag_path(char *out, const char *name)
{
  const char *dir = getenv("RACE_DIR");
  snprintf(out, PATH_MAX, "%s/%s", dir ? dir : "/tmp", name);
}

int _ZN8eprosima7fastdds3dds17DomainParticipant12set_listenerEPNS1_25DomainParticipantListenerE(
  void *self, void *listener)
{
  /* Fast DDS is loaded by rclpy's extension, out of the global scope RTLD_NEXT searches */
  void *fastdds = dlopen("libfastrtps.so.2.14", RTLD_NOW | RTLD_NOLOAD);
  set_listener_fn real = (set_listener_fn)dlsym(fastdds, SET_LISTENER);
  if (listener == NULL) {
    char slow[PATH_MAX], held[PATH_MAX];
    flag_path(slow, "slow");
    flag_path(held, "held");
    FILE *f = fopen(slow, "w");
    if (f) {
      fclose(f);
    }
    for (int i = 0; i < 1000 && access(held, F_OK) != 0; ++i) {
      usleep(10000);
    }
    fprintf(stderr, "[race] set_listener(nullptr) with a discovery callback %s\n",
            access(held, F_OK) == 0 ? "held in flight" : "NOT held");
  }
  return real(self, listener);
}
