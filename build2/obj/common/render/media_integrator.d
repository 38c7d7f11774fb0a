build2/obj/common/render/media_integrator.o: \
 common/render/media_integrator.c common/render/media_integrator.h \
 common/render/render_job.h common/render/accel.h common/scene/scene.h \
 common/base/vec.h common/scene/motion.h common/scene/scene_limits.h \
 common/scene/camera.h common/scene/sampler.h common/base/rng.h \
 common/scene/light.h common/scene/medium.h common/render/media_track.h \
 common/render/surface.h common/render/photon_map.h \
 common/render/photon_trace.h common/scene/grid.h common/scene/material.h
common/render/media_integrator.h:
common/render/render_job.h:
common/render/accel.h:
common/scene/scene.h:
common/base/vec.h:
common/scene/motion.h:
common/scene/scene_limits.h:
common/scene/camera.h:
common/scene/sampler.h:
common/base/rng.h:
common/scene/light.h:
common/scene/medium.h:
common/render/media_track.h:
common/render/surface.h:
common/render/photon_map.h:
common/render/photon_trace.h:
common/scene/grid.h:
common/scene/material.h:
