// SPDX-License-Identifier: GPL-3.0-or-later
// fiberform: the function object flowRateConvergence (see flowRateConvergence.H).
#include "flowRateConvergence.H"

#include "Time.H"
#include "addToRunTimeSelectionTable.H"
#include "surfaceFields.H"

namespace Foam
{
namespace functionObjects
{
    defineTypeNameAndDebug(flowRateConvergence, 0);
    addToRunTimeSelectionTable(functionObject, flowRateConvergence, dictionary);
}
}

Foam::functionObjects::flowRateConvergence::flowRateConvergence
(
    const word& name,
    const Time& runTime,
    const dictionary& dict
)
:
    fvMeshFunctionObject(name, runTime, dict),
    patchName_(),
    patchi_(-1),
    window_(0),
    tolerance_(0),
    history_(0)
{
    read(dict);
}

bool Foam::functionObjects::flowRateConvergence::read(const dictionary& dict)
{
    fvMeshFunctionObject::read(dict);
    patchName_ = dict.get<word>("patch");
    patchi_ = mesh_.boundaryMesh().findPatchID(patchName_);
    if (patchi_ < 0)
    {
        FatalIOErrorInFunction(dict)
            << "flowRateConvergence " << name() << ": no patch named " << patchName_
            << "; patches: " << mesh_.boundaryMesh().names() << exit(FatalIOError);
    }
    window_ = dict.get<label>("window");
    tolerance_ = dict.get<scalar>("tolerance");
    if (window_ < 2 || !(tolerance_ > 0))
    {
        FatalIOErrorInFunction(dict)
            << "flowRateConvergence " << name() << ": need window >= 2 (iterations) and "
            << "tolerance > 0 (relative range); got window " << window_ << ", tolerance "
            << tolerance_ << exit(FatalIOError);
    }
    history_ = fiberform::SlidingWindow(static_cast<std::size_t>(window_));
    // a resumed solve: the outflows of the iterations before its start time (the killed run's
    // recorded history), so that it stops where an uninterrupted solve would
    const scalarList initial(dict.lookupOrDefault<scalarList>("initial", scalarList()));
    for (const scalar q : initial)
    {
        history_.push(q);
    }
    Info<< type() << " " << name() << ": stop when sum(phi) over patch " << patchName_
        << " varies by at most " << tolerance_ << " of its mean over " << window_
        << " iterations (" << initial.size() << " earlier values)" << endl;
    return true;
}

bool Foam::functionObjects::flowRateConvergence::execute()
{
    const surfaceScalarField& phi = lookupObject<surfaceScalarField>("phi");
    const scalar q = gSum(phi.boundaryField()[patchi_]);
    history_.push(q);
    if (history_.converged(tolerance_))
    {
        Info<< type() << " " << name() << ": flow rate through " << patchName_
            << " converged (range " << history_.relative_range() << " of the mean over the last "
            << window_ << " iterations, tolerance " << tolerance_ << "): stopping at "
            << time_.timeName() << endl;
        const_cast<Time&>(time_).writeAndEnd();
    }
    return true;
}

bool Foam::functionObjects::flowRateConvergence::write()
{
    return true;
}
