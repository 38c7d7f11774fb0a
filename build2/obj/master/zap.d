build2/obj/master/zap.o: master/zap.c master/zap.h common/wire/net.h \
 common/wire/proto.h common/wire/blob.h common/render/tile.h \
 common/image/imgio.h common/scene/scene.h common/base/vec.h \
 common/scene/motion.h common/scene/scene_limits.h common/base/log.h
master/zap.h:
common/wire/net.h:
common/wire/proto.h:
common/wire/blob.h:
common/render/tile.h:
common/image/imgio.h:
common/scene/scene.h:
common/base/vec.h:
common/scene/motion.h:
common/scene/scene_limits.h:
common/base/log.h:
