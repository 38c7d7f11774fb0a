build2/obj/master/fold.o: master/fold.c master/fold.h \
 common/image/imgio.h common/render/tile.h common/scene/scene.h \
 common/base/vec.h common/scene/motion.h common/scene/scene_limits.h \
 common/base/log.h common/render/integrator.h common/render/render_job.h \
 common/render/accel.h common/scene/camera.h common/scene/sampler.h \
 common/base/rng.h common/scene/light.h
master/fold.h:
common/image/imgio.h:
common/render/tile.h:
common/scene/scene.h:
common/base/vec.h:
common/scene/motion.h:
common/scene/scene_limits.h:
common/base/log.h:
common/render/integrator.h:
common/render/render_job.h:
common/render/accel.h:
common/scene/camera.h:
common/scene/sampler.h:
common/base/rng.h:
common/scene/light.h:
