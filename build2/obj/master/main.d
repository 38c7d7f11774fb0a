build2/obj/master/main.o: master/main.c common/base/cli.h master/launch.h \
 common/base/log.h master/master.h master/opts.h common/scene/medium.h \
 common/scene/scene_limits.h common/base/vec.h common/wire/net.h \
 common/wire/proto.h common/wire/blob.h common/render/tile.h \
 common/image/imgio.h common/scene/scene.h common/scene/motion.h \
 common/scene/sampler.h common/base/rng.h
common/base/cli.h:
master/launch.h:
common/base/log.h:
master/master.h:
master/opts.h:
common/scene/medium.h:
common/scene/scene_limits.h:
common/base/vec.h:
common/wire/net.h:
common/wire/proto.h:
common/wire/blob.h:
common/render/tile.h:
common/image/imgio.h:
common/scene/scene.h:
common/scene/motion.h:
common/scene/sampler.h:
common/base/rng.h:
