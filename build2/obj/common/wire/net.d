build2/obj/common/wire/net.o: common/wire/net.c common/wire/net.h \
 common/wire/proto.h common/wire/blob.h common/render/tile.h \
 common/image/imgio.h common/scene/scene.h common/base/vec.h \
 common/scene/motion.h common/scene/scene_limits.h common/base/log.h
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
