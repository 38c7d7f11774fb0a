build2/obj/master/journal.o: master/journal.c master/journal.h \
 common/wire/blob.h common/render/tile.h common/image/imgio.h \
 common/scene/scene.h common/base/vec.h common/scene/motion.h \
 common/scene/scene_limits.h common/base/bytes.h common/base/log.h
master/journal.h:
common/wire/blob.h:
common/render/tile.h:
common/image/imgio.h:
common/scene/scene.h:
common/base/vec.h:
common/scene/motion.h:
common/scene/scene_limits.h:
common/base/bytes.h:
common/base/log.h:
