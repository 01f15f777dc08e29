/*
 * rmw_fastrtps' ParticipantListener::on_publisher_discovery, held 1 s once $RACE_DIR/slow
 * exists: a discovery callback in flight (Fast DDS counts it in callback_counter_).
 */
#define _GNU_SOURCE
#include <dlfcn.h>
#include <limits.h>
#include <stdio.h>
#include <stdlib.h>
#include <unistd.h>

#define ON_PUBLISHER_DISCOVERY \
  "_ZN19ParticipantListener22on_publisher_discoveryEPN8eprosima7fastdds3dds17DomainParticipantEON" \
  "S0_8fastrtps4rtps19WriterDiscoveryInfoE"

typedef void (*discovery_fn)(void *, void *, void *);

void _ZN19ParticipantListener22on_publisher_discoveryEPN8eprosima7fastdds3dds17DomainParticipantEONS0_8fastrtps4rtps19WriterDiscoveryInfoE(
  void *self, void *participant, void *info)
{
  /* rmw is loaded by rclpy's extension, out of the global scope RTLD_NEXT searches */
  void *rmw = dlopen("librmw_fastrtps_shared_cpp.so", RTLD_NOW | RTLD_NOLOAD);
  discovery_fn real = (discovery_fn)dlsym(rmw, ON_PUBLISHER_DISCOVERY);
  const char *dir = getenv("RACE_DIR");
  char slow[PATH_MAX], held[PATH_MAX];
  snprintf(slow, PATH_MAX, "%s/slow", dir ? dir : "/tmp");
  snprintf(held, PATH_MAX, "%s/held", dir ? dir : "/tmp");
  if (access(slow, F_OK) == 0 && access(held, F_OK) != 0) {
    FILE *f = fopen(held, "w");
    if (f) {
      fclose(f);
    }
    sleep(1);             /* well within a node's clean-up bound (3 s) */
  }
  real(self, participant, info);
}
