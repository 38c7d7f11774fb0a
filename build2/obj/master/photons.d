build2/obj/master/photons.o: master/photons.c master/photons.h \
 common/base/asset.h master/opts.h common/scene/scene.h common/base/vec.h \
 common/scene/motion.h common/scene/scene_limits.h common/wire/blob.h \
 common/base/log.h common/base/rng.h common/render/media_track.h \
 common/render/surface.h common/render/accel.h common/scene/light.h \
 common/scene/medium.h common/render/photon_map.h common/render/passes.h \
 common/render/photon_trace.h common/render/render_job.h \
 common/scene/camera.h common/scene/sampler.h
master/photons.h:
common/base/asset.h:
master/opts.h:
common/scene/scene.h:
common/base/vec.h:
common/scene/motion.h:
common/scene/scene_limits.h:
common/wire/blob.h:
common/base/log.h:
common/base/rng.h:
common/render/media_track.h:
common/render/surface.h:
common/render/accel.h:
common/scene/light.h:
common/scene/medium.h:
common/render/photon_map.h:
common/render/passes.h:
common/render/photon_trace.h:
common/render/render_job.h:
common/scene/camera.h:
common/scene/sampler.h:
