build2/obj/master/outnames.o: master/outnames.c master/outnames.h \
 common/base/asset.h master/opts.h master/output.h common/image/imgio.h \
 common/base/log.h
master/outnames.h:
common/base/asset.h:
master/opts.h:
master/output.h:
common/image/imgio.h:
common/base/log.h:
