build2/obj/master/master.o: master/master.c master/master.h master/opts.h \
 common/base/asset.h common/wire/blob.h common/image/imgio.h \
 master/journal.h common/render/tile.h common/scene/scene.h \
 common/base/vec.h common/scene/motion.h common/scene/scene_limits.h \
 master/outnames.h master/launch.h common/base/log.h common/wire/net.h \
 common/wire/proto.h master/zap.h master/output.h master/fold.h \
 master/adapt.h master/photons.h master/sched.h \
 common/render/integrator.h common/render/render_job.h \
 common/render/accel.h common/scene/camera.h common/scene/sampler.h \
 common/base/rng.h common/scene/light.h common/render/media_integrator.h \
 common/scene/medium.h common/render/photon_trace.h \
 common/scene/scene_json.h
master/master.h:
master/opts.h:
common/base/asset.h:
common/wire/blob.h:
common/image/imgio.h:
master/journal.h:
common/render/tile.h:
common/scene/scene.h:
common/base/vec.h:
common/scene/motion.h:
common/scene/scene_limits.h:
master/outnames.h:
master/launch.h:
common/base/log.h:
common/wire/net.h:
common/wire/proto.h:
master/zap.h:
master/output.h:
master/fold.h:
master/adapt.h:
master/photons.h:
master/sched.h:
common/render/integrator.h:
common/render/render_job.h:
common/render/accel.h:
common/scene/camera.h:
common/scene/sampler.h:
common/base/rng.h:
common/scene/light.h:
common/render/media_integrator.h:
common/scene/medium.h:
common/render/photon_trace.h:
common/scene/scene_json.h:
