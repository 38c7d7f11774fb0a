build2/obj/common/wire/proto.o: common/wire/proto.c common/wire/proto.h \
 common/wire/blob.h common/render/tile.h common/image/imgio.h \
 common/scene/scene.h common/base/vec.h common/scene/motion.h \
 common/scene/scene_limits.h common/base/bytes.h common/base/log.h
common/wire/proto.h:
common/wire/blob.h:
common/render/tile.h:
common/image/imgio.h:
common/scene/scene.h:
common/base/vec.h:
common/scene/motion.h:
common/scene/scene_limits.h:
common/base/bytes.h:
common/base/log.h:
